"""package.xml names a rosdep key for every third-party import of the installed modules (issue
#20: mcap, scipy, rcl_interfaces and Pillow were missing, and a test key was no rosdep key).

The imports are derived from the source: every top-level module imported by the Python packages
setup.py installs (ast, no import), minus the standard library and the packages themselves.
Each must map to a key (ROSDEP) that package.xml declares as an exec_depend. Every key package.xml
names must be one of KNOWN_KEYS, the keys checked by hand against ros/rosdistro at commit
8468e88ccd (2026-08-22): rosdep/python.yaml for the pip and Debian keys (it has no key for the
pip package mcap; mcap-ros2-support installs it as its dependency), jazzy/distribution.yaml for
the ROS packages.
"""

from __future__ import annotations

import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from setuptools import find_packages

REPO = Path(__file__).resolve().parent.parent
#: top-level import -> the rosdep key that installs it
ROSDEP = {
    "numpy": "python3-numpy",
    "yaml": "python3-yaml",
    "matplotlib": "python3-matplotlib",
    "scipy": "python3-scipy",
    "numba": "python3-numba",
    "rosbags": "python3-rosbags-pip",
    "mcap": "mcap-ros2-support",
    "mcap_ros2": "mcap-ros2-support",
    "pyarrow": "python3-pyarrow",
    "dask": "python3-dask",
    "distributed": "python3-distributed",
    **{
        ros: ros
        for ros in (
            "rclpy",
            "rcl_interfaces",
            "ament_index_python",
            "builtin_interfaces",
            "std_msgs",
            "sensor_msgs",
            "geometry_msgs",
            "trajectory_msgs",
            "visualization_msgs",
            "diagnostic_msgs",
            "manipulator_kinematics_interfaces",
        )
    },
}
#: keys needed without an import of ours: (key, why, a text in the source or launch files that needs it)
INDIRECT = (
    ("python3-pil", "matplotlib's PillowWriter writes the GIFs", "PillowWriter"),
    ("ros2launch", "ros2 launch runs launch/*.launch.xml", "<launch>"),
    ("robot_state_publisher", "the launch files start it", 'pkg="robot_state_publisher"'),
)
KNOWN_KEYS = {*ROSDEP.values(), *(key for key, _, _ in INDIRECT), "python3-pytest", "pinocchio"}


def depends(kind: str) -> set[str]:
    root = ET.parse(REPO / "package.xml").getroot()
    return {element.text.strip() for element in root.iter(kind)}


def installed_sources() -> list[Path]:
    packages = find_packages(str(REPO), exclude=["test", "test.*", "benchmarks", "scripts"])
    assert "manipulator_kinematics" in packages and len(packages) >= 6, packages
    return [path for package in packages for path in (REPO / package.replace(".", "/")).glob("*.py")]


def third_party_imports() -> dict[str, set[str]]:
    ours = {p.split(".")[0] for p in find_packages(str(REPO))}
    found: dict[str, set[str]] = {}
    for path in installed_sources():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module]
                if isinstance(node, ast.ImportFrom) and node.level == 0
                else []
            )
            for name in names:
                top = name.split(".")[0]
                if top not in sys.stdlib_module_names and top not in ours:
                    found.setdefault(top, set()).add(str(path.relative_to(REPO)))
    return found


def test_every_runtime_import_has_an_exec_depend() -> None:
    imports = third_party_imports()
    assert {"numpy", "mcap", "scipy", "rcl_interfaces", "rclpy"} <= set(imports)  # the derivation works
    unmapped = sorted(set(imports) - set(ROSDEP))
    assert not unmapped, f"imports without a rosdep key in this test's table: {unmapped}"
    keys = {ROSDEP[name]: sorted(files)[0] for name, files in imports.items()}
    undeclared = {key: file for key, file in keys.items() if key not in depends("exec_depend")}
    assert not undeclared, f"package.xml lacks exec_depend for {undeclared}"


def test_indirect_dependencies_are_still_needed_and_declared() -> None:
    texts = "\n".join(
        [p.read_text(encoding="utf-8") for p in installed_sources()]
        + [p.read_text(encoding="utf-8") for p in (REPO / "launch").glob("*.launch.xml")]
    )
    for key, why, needed_by in INDIRECT:
        assert needed_by in texts, f"{key} ({why}): nothing needs it any more"
        assert key in depends("exec_depend"), f"package.xml lacks exec_depend {key} ({why})"


def test_every_key_is_a_rosdep_key_and_none_is_stale() -> None:
    declared = depends("exec_depend") | depends("test_depend") | depends("depend")
    assert declared - KNOWN_KEYS == set(), "not checked against rosdistro: add it to KNOWN_KEYS with evidence"
    needed = {ROSDEP[name] for name in third_party_imports()} | {key for key, _, _ in INDIRECT}
    stale = depends("exec_depend") - needed
    assert not stale, f"exec_depend nothing imports: {sorted(stale)}"
