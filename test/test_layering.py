"""The layering rules of the package, checked on the source: the shared package imports no machine
package (machines are found through the registry), and nothing uses rclpy's private internals."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from manipulator_kinematics.registry import Hook, machines

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO / "manipulator_kinematics"
MACHINE_PACKAGES = sorted(p.parent.name for p in REPO.glob("*_kinematics/__init__.py") if p.parent != SHARED)


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_the_shared_package_imports_no_machine_package() -> None:
    assert {"excavator_kinematics", "scara_kinematics"} <= set(MACHINE_PACKAGES)
    offenders = {
        str(path.relative_to(REPO)): sorted(
            m for m in imported_modules(path) if m.split(".")[0] in MACHINE_PACKAGES
        )
        for path in SHARED.rglob("*.py")
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_no_rclpy_private_internals() -> None:
    private = ("rclpy.impl", "rclpy._rclpy_pybind11")
    offenders = {
        str(path.relative_to(REPO)): sorted(m for m in imported_modules(path) if m.startswith(private))
        for folder in [SHARED, *(REPO / m for m in MACHINE_PACKAGES)]
        for path in folder.rglob("*.py")
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_every_machine_package_is_registered_under_its_name() -> None:
    registered = {m.factory.__module__.split(".")[0] for m in machines().values()}
    assert registered == set(MACHINE_PACKAGES)
    for name, machine in machines().items():
        assert machine.name == name and machine.schema and machine.topics


@pytest.mark.ros
def test_loading_the_registry_imports_no_hook_code_and_every_hook_resolves() -> None:
    # Every node loads the registry at start-up: the bag, URDF and drawing hooks wait for a call.
    code = (
        "import sys; from manipulator_kinematics.registry import machines; machines(); "
        "print(' '.join(sorted(sys.modules)))"
    )
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    hook_modules = (
        "manipulator_kinematics.bag",
        "manipulator_kinematics.urdf",
        "manipulator_kinematics.scene",
        "excavator_kinematics.evaluation",
        "excavator_kinematics.scene",
        "rosbags",
        "mcap",
    )
    assert [m for m in loaded.stdout.split() if m.startswith(hook_modules)] == []
    hooks = [
        (m.name, getattr(m, field))
        for m in machines().values()
        for field in ("analyse", "synthesize", "urdf", "scene", "monitored", "read_surface")
        if isinstance(getattr(m, field), Hook)
    ]
    assert len(hooks) >= 3 * len(machines())
    for name, hook in hooks:
        assert callable(hook.resolve()), (name, hook)
