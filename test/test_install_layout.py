"""The `ros2 run` layout: both packages built with colcon into a temporary install space.

One colcon build per module (about 35-40 s on 2 cores, the interface package's C/C++ is most of
it), into a temporary directory, so the repo gets no build/, install/ or log/. Then the install
space is used the way a sourced workspace would be: a shell that exported AMENT_PREFIX_PATH to
the venv and sourced install/setup.bash (platform notes, item 6).
"""

from __future__ import annotations

import ast
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parent.parent
PKG = "manipulator_kinematics"
IFACE = "manipulator_kinematics_interfaces"
VENV = Path(sys.prefix)
PYVER = f"python{sys.version_info.major}.{sys.version_info.minor}"


def console_scripts() -> dict[str, str]:
    """name -> 'module:function' of every console script declared in setup.py."""
    tree = ast.parse((REPO / "setup.py").read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                if isinstance(key, ast.Constant) and key.value == "console_scripts":
                    entries = ast.literal_eval(value)
                    pairs = (entry.split("=", 1) for entry in entries)
                    return {name.strip(): target.strip() for name, target in pairs}
    raise AssertionError("setup.py declares no console_scripts")


def _sourced_env(install: Path) -> dict[str, str]:
    """Environment of a fresh shell that put the venv first and sourced install/setup.bash."""
    base = {
        "HOME": os.environ.get("HOME", "/root"),
        "PATH": f"{VENV / 'bin'}:/usr/local/bin:/usr/bin:/bin",
        "VIRTUAL_ENV": str(VENV),
        "AMENT_PREFIX_PATH": str(VENV),
        "LANG": "C.UTF-8",
    }
    for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "TMPDIR", "MPLBACKEND"):
        if key in os.environ:
            base[key] = os.environ[key]
    dump = subprocess.run(
        ["bash", "-c", f'. "{install}/setup.bash" && env -0'],
        env=base,
        capture_output=True,
        check=True,
        timeout=60,
    ).stdout.decode()
    return dict(item.split("=", 1) for item in dump.split("\0") if "=" in item)


@pytest.fixture(scope="module")
def colcon_install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    colcon = VENV / "bin" / "colcon"
    assert colcon.is_file(), f"{colcon} missing: run scripts/bootstrap.sh"
    assert shutil.which("cmake"), "cmake is not on PATH"
    work = tmp_path_factory.mktemp("colcon")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("COLCON_", "AMENT_", "CMAKE_"))}
    env.pop("PYTHONPATH", None)
    env.update(
        PATH=f"{VENV / 'bin'}:{env.get('PATH', '/usr/bin:/bin')}",
        VIRTUAL_ENV=str(VENV),
        AMENT_PREFIX_PATH=str(VENV),  # platform notes item 3
        CMAKE_PREFIX_PATH=str(VENV),
        PYTHONDONTWRITEBYTECODE="1",  # no __pycache__ in the source tree from setup.py
    )
    command = [
        str(colcon),
        "--log-base",
        str(work / "log"),
        "build",
        "--base-paths",
        str(REPO),
        str(REPO / IFACE),
        "--build-base",
        str(work / "build"),
        "--install-base",
        str(work / "install"),
        "--event-handlers",
        "console_direct-",
        "console_cohesion-",
        "status-",
        "summary+",
        "--cmake-args",
        "-DBUILD_TESTING=OFF",
    ]
    started = time.monotonic()
    result = subprocess.run(
        command,
        cwd=work,
        env=env,
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=900,
    )
    elapsed = time.monotonic() - started
    assert result.returncode == 0, f"colcon build failed:\n{result.stdout[-6000:]}\n{result.stderr[-6000:]}"
    print(f"colcon build of {PKG} + {IFACE}: {elapsed:.1f} s")
    shutil.rmtree(work / "build", ignore_errors=True)  # keep only install/ (saves ~100 MB)
    return work / "install"


@pytest.fixture(scope="module")
def install_env(colcon_install: Path) -> dict[str, str]:
    return _sourced_env(colcon_install)


def _run_python(env: dict[str, str], code: str) -> str:
    result = subprocess.run(
        [str(VENV / "bin" / "python"), "-c", code],
        env=env,
        cwd="/",
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
    )
    assert result.returncode == 0, f"python -c failed:\n{result.stdout}\n{result.stderr}"
    return result.stdout


def test_no_build_artifacts_in_repo(colcon_install: Path) -> None:
    for name in ("build", "install", "log"):
        assert not (REPO / name / "COLCON_IGNORE").exists(), f"colcon wrote {REPO / name}"


def test_every_console_script_is_an_executable_in_lib(colcon_install: Path) -> None:
    lib = colcon_install / PKG / "lib" / PKG
    scripts = console_scripts()
    assert scripts, "no console scripts"
    for name in scripts:
        exe = lib / name
        assert exe.is_file(), f"{exe} missing (ros2 run {PKG} {name} would fail)"
        assert os.access(exe, os.X_OK), f"{exe} is not executable"
        shebang = exe.read_text(encoding="utf-8").splitlines()[0]
        assert shebang.startswith("#!"), f"{exe}: no shebang"
        interpreter = Path(shebang[2:].strip().split()[0])
        assert interpreter.is_file() and os.access(interpreter, os.X_OK), f"{exe}: bad {shebang}"


def test_bag_tools_are_installed_under_names_that_cannot_clash(colcon_install: Path) -> None:
    """The bag tools land on a user's PATH (venv/bin, install/<pkg>/bin) and in lib/<pkg>/ as
    mk_record, mk_replay, mk_evaluate (like mk_urdf), never under bare generic names."""
    lib = colcon_install / PKG / "lib" / PKG
    scripts = console_scripts()
    for name, module in (("mk_record", "record"), ("mk_replay", "replay"), ("mk_evaluate", "evaluate")):
        assert scripts.get(name) == f"{PKG}.bag.{module}:main", name
        assert (lib / name).is_file(), f"{lib / name} missing"
        assert module not in scripts and not (lib / module).exists(), module


def test_ament_index_marker_package_xml_and_config(colcon_install: Path) -> None:
    prefix = colcon_install / PKG
    marker = prefix / "share" / "ament_index" / "resource_index" / "packages" / PKG
    assert marker.is_file(), f"{marker} missing: ament_index cannot find {PKG}"
    assert (prefix / "share" / PKG / "package.xml").is_file()
    shipped = sorted(p.name for p in (REPO / "config").glob("*.yaml"))
    assert shipped, "config/*.yaml: nothing to install"
    installed = sorted(p.name for p in (prefix / "share" / PKG / "config").glob("*.yaml"))
    assert installed == shipped


def test_launch_files_and_urdfs_are_installed(colcon_install: Path) -> None:
    """ros2 launch finds share/<pkg>/launch/*.launch.xml; they read the URDFs from share/<pkg>/urdf."""
    share = colcon_install / PKG / "share" / PKG
    for folder, pattern in (("launch", "*.launch.xml"), ("urdf", "*.urdf")):
        shipped = sorted(p.name for p in (REPO / folder).glob(pattern))
        assert shipped, f"{folder}/{pattern}: nothing to install"
        assert sorted(p.name for p in (share / folder).glob(pattern)) == shipped, folder


def test_ament_index_resolves_to_install(colcon_install: Path, install_env: dict[str, str]) -> None:
    out = _run_python(
        install_env,
        (
            "from ament_index_python.packages import get_package_prefix, get_package_share_directory\n"
            f"print(get_package_prefix('{PKG}'))\n"
            f"print(get_package_share_directory('{PKG}'))\n"
            f"print(get_package_prefix('{IFACE}'))\n"
        ),
    )
    prefix, share, iface_prefix = out.split()
    assert Path(prefix) == colcon_install / PKG
    assert Path(share) == colcon_install / PKG / "share" / PKG
    assert Path(iface_prefix) == colcon_install / IFACE


def test_python_packages_and_config_come_from_install(
    colcon_install: Path, install_env: dict[str, str]
) -> None:
    """Every console script's entry point resolves to a callable in the installed copy."""
    site = colcon_install / PKG / "lib" / PYVER / "site-packages"
    targets = sorted(set(console_scripts().values()))
    config = sorted(p.name for p in (REPO / "config").glob("*.yaml"))[0]
    out = _run_python(
        install_env,
        (
            "import importlib\n"
            f"for target in {targets!r}:\n"
            "    module_name, function = target.split(':')\n"
            "    module = importlib.import_module(module_name)\n"
            "    assert callable(getattr(module, function, None)), f'{target}: no such function'\n"
            "    print(module.__file__)\n"
            "from manipulator_kinematics.param_files import config_path\n"
            f"print(config_path({config!r}))\n"
        ),
    )
    *files, config_file = out.split()
    assert len(files) == len(targets)
    for file in files:
        assert Path(file).is_relative_to(site), f"{file} not imported from {site}"
    # Installed, the package has no config/ beside it: the file comes from share/ via ament_index.
    assert Path(config_file) == colcon_install / PKG / "share" / PKG / "config" / config


def test_interfaces_import_from_install(colcon_install: Path, install_env: dict[str, str]) -> None:
    out = _run_python(
        install_env,
        (
            f"import {IFACE}\n"
            f"from {IFACE}.srv import SolveIK, SolveFK\n"
            f"from {IFACE}.msg import KinematicsErrorCodes\n"
            "request = SolveIK.Request(mode='position')\n"
            "assert SolveFK.Response() is not None and KinematicsErrorCodes() is not None\n"
            f"print({IFACE}.__file__)\n"
        ),
    )
    assert Path(out.strip()).is_relative_to(colcon_install / IFACE), out


def test_installed_executable_runs_like_ros2_run(
    colcon_install: Path, install_env: dict[str, str], tmp_path: Path
) -> None:
    """Execute lib/<pkg>/<exe> directly (what `ros2 run` does), see its node join the graph,
    then stop it with SIGINT and expect a clean exit."""
    scripts = console_scripts()
    name = "excavator_forward"
    if name not in scripts:
        pytest.skip(f"{name} is not declared in setup.py")
    exe = colcon_install / PKG / "lib" / PKG / name
    node_name = f"mk_layout_probe_{os.getpid()}"
    log_path = tmp_path / f"{name}.log"

    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    observer = rclpy.create_node(f"mk_layout_observer_{os.getpid()}", context=context)
    with open(log_path, "w", encoding="utf-8") as log:
        process = subprocess.Popen(
            [str(exe), "--ros-args", "-r", f"__node:={node_name}"],
            env=install_env,
            cwd=tmp_path,
            stdout=log,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
        )
    try:
        deadline = time.monotonic() + 30.0
        seen = False
        while time.monotonic() < deadline and process.poll() is None:
            if node_name in observer.get_node_names():
                seen = True
                break
            time.sleep(0.1)
        running = process.poll() is None
        log_text = log_path.read_text(encoding="utf-8", errors="replace")
        assert running, f"{exe} exited with {process.returncode}:\n{log_text}"
        assert seen, f"node {node_name} never appeared in the ROS graph:\n{log_text}"
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
            try:
                process.wait(15)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(15)
        observer.destroy_node()
        rclpy.shutdown(context=context)
    log_text = log_path.read_text(encoding="utf-8", errors="replace")
    assert process.returncode == 0, f"{exe} exit code {process.returncode} after SIGINT:\n{log_text}"
