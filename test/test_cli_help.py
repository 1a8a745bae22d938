"""Every executable of the package answers -h and --help with what it does and exits 0, without
starting ROS (issue: a node that ignored --help started and served instead)."""

from __future__ import annotations

import contextlib
import io
import re
import subprocess
import sys
from importlib.metadata import distribution

import pytest

from manipulator_kinematics.help_text import plain
from manipulator_kinematics.node_util import console_script

pytestmark = pytest.mark.ros

ENTRY_POINTS = sorted(
    (e for e in distribution("manipulator_kinematics").entry_points if e.group == "console_scripts"),
    key=lambda e: e.name,
)


def in_process(entry, flag: str, monkeypatch: pytest.MonkeyPatch) -> tuple[int, str]:
    """The entry point's exit code and output for ``<exe> <flag>``, as its console script runs it."""
    monkeypatch.setattr(sys, "argv", [entry.name, flag])
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        try:
            code = entry.load()()
        except SystemExit as exit_:
            code = exit_.code
    return int(code or 0), out.getvalue()


@pytest.mark.parametrize("flag", ["-h", "--help"])
@pytest.mark.parametrize("entry", ENTRY_POINTS, ids=lambda e: e.name)
def test_every_executable_answers_help(entry, flag: str, monkeypatch: pytest.MonkeyPatch) -> None:
    code, text = in_process(entry, flag, monkeypatch)
    assert code == 0, (entry.name, text)
    assert text.startswith(f"usage: {entry.name}") and len(text.splitlines()) >= 5, text[:300]


def test_the_console_scripts_answer_help_too() -> None:
    assert len(ENTRY_POINTS) >= 20
    for exe in ("excavator_forward", "tool_changer_ik_server", "machine_markers", "mk_record"):
        result = subprocess.run([console_script(exe), "--help"], capture_output=True, text=True, timeout=120)
        assert result.returncode == 0 and result.stdout.startswith(f"usage: {exe}"), (exe, result.stderr)


def test_a_node_help_lists_its_parameters_with_defaults_and_topics(monkeypatch: pytest.MonkeyPatch) -> None:
    entries = {e.name: e for e in ENTRY_POINTS}
    text = in_process(entries["excavator_forward"], "--help", monkeypatch)[1]
    for line in (
        "hydraulic_machine.links.h_link.length = 0.58",
        "excavator.base_height = 0.0",
        "swing_max_age = 0.1",
        "topics.bucket_pose = 'bucket_pose'",
        "qos_depth = 400",
    ):
        assert line in text, line
    server = in_process(entries["tool_changer_ik_server"], "-h", monkeypatch)[1]
    assert "solve_ik" in server and "solve_fk" in server and "base_frame = 'base_link'" in server
    excavator = in_process(entries["excavator_ik_server"], "--help", monkeypatch)[1]
    assert "solve_ik" in excavator and "hydraulic_machine.bodies.boom.pins.arm_pin = " in excavator


@pytest.mark.parametrize("entry", ENTRY_POINTS, ids=lambda e: e.name)
def test_help_is_plain_text(entry, monkeypatch: pytest.MonkeyPatch) -> None:
    """No reST markup from the docstrings (issue #20: ``:meth:``, ````literal````)."""
    text = in_process(entry, "--help", monkeypatch)[1]
    assert not re.search(r"``|:[a-z]+:`", text), re.search(r".*(``|:[a-z]+:`).*", text)[0]


def test_plain_reduces_roles_and_literals() -> None:
    assert plain("A :meth:`Excavator.state` on ``joint_states``; :class:`~a.b.Scene`, :func:`f <g.h>`") == (
        "A Excavator.state on joint_states; Scene, f"
    )
