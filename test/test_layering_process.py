"""The registry loaded in a fresh interpreter (ros tier: a child process) imports no hook code; the
source-level rules are in test_layering.py."""

from __future__ import annotations

import subprocess
import sys

import pytest

from manipulator_kinematics.registry import Hook, machines

pytestmark = pytest.mark.ros


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
        "excavator_kinematics.tools.evaluation",
        "excavator_kinematics.tools.scene",
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
