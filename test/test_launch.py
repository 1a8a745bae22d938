"""launch/*.launch.xml (ROS 2 launch XML) are consistent with the package (issue #20).

Each is parsed (xml.etree) and checked (test_launch_service.py runs them with launch itself):
one per registered machine with a URDF plus the excavator chain; every node's package and
executable exist (ours: a console script of setup.py; another package: named in package.xml);
every params file and URDF a file reads exists in config/ or urdf/ (installed to share/ by
setup.py, checked after a colcon build by test_install_layout.py); every argument is documented,
used, and every $(var ...) declared; namespace, params_file and frame_prefix are arguments of
every file; every node of ours that publishes or accepts frame_ids, and robot_state_publisher,
gets frame_prefix; includes name existing files and declared arguments.
"""

from __future__ import annotations

import contextlib
import io
import re
import sys
import xml.etree.ElementTree as ET
from functools import cache
from importlib.metadata import distribution
from pathlib import Path

import pytest

from manipulator_kinematics.registry import machines

REPO = Path(__file__).resolve().parent.parent
LAUNCH = REPO / "launch"
PKG = "manipulator_kinematics"
SHARE = f"$(find-pkg-share {PKG})/"
FILES = sorted(LAUNCH.glob("*.launch.xml"))
VAR = re.compile(r"\$\(var ([A-Za-z_][A-Za-z0-9_]*)\)")
SHARED = re.compile(re.escape(SHARE) + r"([A-Za-z0-9_./]+)")
REQUIRED_ARGS = {"namespace", "params_file", "frame_prefix"}


def console_scripts() -> dict:
    return {e.name: e for e in distribution(PKG).entry_points if e.group == "console_scripts"}


@cache
def help_of(exe: str) -> str:
    """``exe --help`` (in-process, as test_cli_help.py runs it)."""
    entry, argv = console_scripts()[exe], sys.argv
    out = io.StringIO()
    try:
        sys.argv = [exe, "--help"]
        with contextlib.redirect_stdout(out):
            entry.load()()
    finally:
        sys.argv = argv
    return out.getvalue()


def exec_depends() -> set[str]:
    return {e.text.strip() for e in ET.parse(REPO / "package.xml").getroot().iter("exec_depend")}


def test_one_file_per_machine_and_the_excavator_chain() -> None:
    names = {path.name for path in FILES}
    for name, machine in machines().items():
        if machine.urdf is not None:
            assert f"{name}.launch.xml" in names, name
    assert "excavator_chain.launch.xml" in names


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_arguments_are_documented_used_and_declared(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    root = ET.fromstring(text)
    assert root.tag == "launch"
    args = {a.get("name"): a for a in root.findall("arg")}
    assert set(args) >= REQUIRED_ARGS, set(args)
    for name, arg in args.items():
        assert (arg.get("description") or "").strip(), f"{path.name}: argument {name} has no description"
        assert f"$(var {name})" in text, f"{path.name}: argument {name} is never used"
    lets = {let.get("name") for let in root.iter("let")}
    undeclared = set(VAR.findall(text)) - set(args) - lets
    assert not undeclared, f"{path.name}: $(var ...) of undeclared arguments {undeclared}"


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_nodes_exist_and_read_existing_files(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    root = ET.fromstring(text)
    scripts, others = console_scripts(), exec_depends()
    nodes = list(root.iter("node"))
    assert nodes or root.find("include") is not None
    for node in nodes:
        pkg, exe = node.get("pkg"), node.get("exec")
        if pkg == PKG:
            assert exe in scripts, f"{path.name}: {exe} is no console script of {PKG}"
        else:
            assert pkg in others, f"{path.name}: package {pkg} is not an exec_depend of package.xml"
        assert node.get("namespace") == "$(var namespace)", f"{path.name}: {exe} ignores the namespace"
    for relative in SHARED.findall(text):
        folder = relative.split("/", 1)[0]
        assert folder in ("config", "urdf", "launch"), relative
        assert (REPO / relative).is_file(), f"{path.name}: {relative} does not exist"
    setup = (REPO / "setup.py").read_text(encoding="utf-8")
    for folder in {r.split("/", 1)[0] for r in SHARED.findall(text)}:
        assert f'f"share/{{PACKAGE}}/{folder}"' in setup, f"setup.py does not install {folder}/"
    for param in root.iter("param"):
        source = param.get("from")
        if source is not None:
            name = VAR.fullmatch(source)
            assert name, f"{path.name}: params file {source} is not an argument"
            default = root.find(f"arg[@name='{name[1]}']").get("default")
            assert default.startswith(SHARE) and default.endswith(".yaml"), default


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_every_frame_id_gets_the_prefix(path: Path) -> None:
    root = ET.parse(path).getroot()
    for node in root.iter("node"):
        params = {p.get("name"): p for p in node.findall("param") if p.get("name")}
        ours = node.get("pkg") == PKG
        needs = "frame_prefix = " in help_of(node.get("exec")) if ours else True
        if needs:
            prefix = params.get("frame_prefix")
            assert prefix is not None and prefix.get("value") == "$(var frame_prefix)", node.get("exec")
            assert prefix.get("type") == "str", "launch_ros reads an empty value as YAML null without it"
        if node.get("exec") == "robot_state_publisher":
            description = params["robot_description"]
            assert description.get("type") == "str" and description.get("value") == "$(var urdf)"


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_includes_name_existing_files_and_their_arguments(path: Path) -> None:
    for include in ET.parse(path).getroot().iter("include"):
        target = include.get("file")
        assert target.startswith(SHARE + "launch/"), target
        included = ET.parse(REPO / target[len(SHARE) :]).getroot()
        known = {a.get("name") for a in included.findall("arg")}
        passed = {a.get("name") for a in include.findall("arg")}
        assert passed <= known, passed - known
        assert passed >= REQUIRED_ARGS, f"{path.name}: the include must pass {REQUIRED_ARGS - passed}"


def test_the_excavator_urdf_follows_urdf_joint_states() -> None:
    root = ET.parse(LAUNCH / "excavator.launch.xml").getroot()
    rsp = next(n for n in root.iter("node") if n.get("exec") == "robot_state_publisher")
    remaps = [(r.get("from"), r.get("to")) for r in rsp.findall("remap")]
    assert remaps == [("joint_states", "urdf_joint_states")]


MACHINE_FILES = [p for p in FILES if p.name != "excavator_chain.launch.xml"]


@pytest.mark.parametrize("path", MACHINE_FILES, ids=lambda p: p.name)
def test_robot_state_publisher_is_optional_first_and_gets_the_urdf_of_the_machine_given(path: Path) -> None:
    """Started before any node of ours (a launch that fails there has started nothing), only with
    robot_state_publisher:=true (the default), with robot_description or else mk_urdf's URDF of
    params_file (not the shipped file's: issue 28 item 1)."""
    root = ET.parse(path).getroot()
    args = {a.get("name"): a.get("default") for a in root.findall("arg")}
    assert args["robot_state_publisher"] == "true" and args["robot_description"] == ""
    first = root.find("group")
    children = list(root)
    assert first is not None and children.index(first) < min(children.index(n) for n in root.findall("node"))
    assert first.get("if") == "$(var robot_state_publisher)"
    machine = path.name.split(".")[0]
    generated = f"$(command '$(exec-in-pkg mk_urdf {PKG}) {machine} --params-file $(var params_file)')"
    assert [let.get("value") for let in first.findall("let")] == ["$(var robot_description)", generated]


def test_the_chain_includes_robot_state_publisher_before_its_simulator() -> None:
    root = ET.parse(LAUNCH / "excavator_chain.launch.xml").getroot()
    children = list(root)
    assert children.index(root.find("include")) < children.index(root.find("node"))
    passed = {a.get("name"): a.get("value") for a in root.find("include").findall("arg")}
    assert passed["robot_state_publisher"] == "$(var robot_state_publisher)"
    assert passed["robot_description"] == "$(var robot_description)"
