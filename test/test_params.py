"""The one params-file walk and the one merge (manipulator_kinematics.param_files): each file parsed
once per process and shared by every reader, never changed through what a reader gets."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from manipulator_kinematics.nodes.base import command_line_values
from manipulator_kinematics.param_files import (
    ConfigError,
    _parse,
    check_ros_arguments,
    given_parameters,
    load_parameters,
    merge,
    ros_arguments,
)


def write(path: Path, document: dict) -> Path:
    path.write_text(yaml.safe_dump(document))
    return path


SCARA = {"scara": {"l2": 0.3, "joint_min": [0.0, 1.0]}}


def test_every_reader_shares_one_parse_of_a_file(tmp_path: Path) -> None:
    path = write(
        tmp_path / "a.yaml",
        {"/**": {"ros__parameters": SCARA}, "/**/node": {"ros__parameters": {"rate": 100.0}}},
    )
    argv = ["exe", "--ros-args", "--params-file", str(path), "-p", "rate:=50.0"]
    before = _parse.cache_info().misses
    check_ros_arguments(argv)
    flat = {"scara.l2": 0.3, "scara.joint_min": [0.0, 1.0], "rate": 50.0}
    assert command_line_values("/node", argv) == flat
    assert given_parameters(argv, "/node") == SCARA | {"rate": 100.0}
    assert load_parameters(path) == SCARA
    assert _parse.cache_info().misses == before + 1


def test_what_a_reader_gets_is_its_own(tmp_path: Path) -> None:
    path = write(tmp_path / "a.yaml", {"/**": {"ros__parameters": SCARA}})
    first = load_parameters(path)
    first["scara"]["joint_min"].append(2.0)
    first["scara"].pop("l2")
    assert load_parameters(path) == {"scara": {"l2": 0.3, "joint_min": [0.0, 1.0]}}


def test_a_changed_file_is_read_again(tmp_path: Path) -> None:
    path = write(tmp_path / "a.yaml", {"/**": {"ros__parameters": {"x": 1.0}}})
    assert load_parameters(path) == {"x": 1.0}
    write(path, {"/**": {"ros__parameters": {"x": 22.0}}})
    assert load_parameters(path) == {"x": 22.0}


def test_later_files_and_sections_win_key_by_key(tmp_path: Path) -> None:
    a = write(
        tmp_path / "a.yaml",
        {
            "/**": {"ros__parameters": {"s": {"a": 1, "b": 2}, "t": 1}},
            "/ns/node": {"ros__parameters": {"s": {"b": 3}}},
        },
    )
    b = write(tmp_path / "b.yaml", {"/**": {"ros__parameters": {"s": {"c": 4}, "t": {"u": 5}}}})
    argv = [
        "exe",
        "--ros-args",
        "--params-file",
        str(a),
        "--params-file",
        str(b),
        "--params-file",
        "missing.yaml",
    ]
    assert given_parameters(argv, "/ns/node") == {"s": {"a": 1, "b": 3, "c": 4}, "t": {"u": 5}}
    assert given_parameters(argv) == {"s": {"a": 1, "b": 2, "c": 4}, "t": {"u": 5}}


def test_merge_leaves_its_layers_as_they_were() -> None:
    base = {"s": {"a": 1, "l": [1.0]}, "leaf": 1}
    over = {"s": {"b": 2}, "leaf": {"now": "a section"}}
    merged = merge(base, over)
    assert merged == {"s": {"a": 1, "l": [1.0], "b": 2}, "leaf": {"now": "a section"}}
    merged["s"]["l"].append(2.0)
    merged["leaf"]["now"] = "changed"
    assert base == {"s": {"a": 1, "l": [1.0]}, "leaf": 1}
    assert over == {"s": {"b": 2}, "leaf": {"now": "a section"}}
    assert merge(over, {"leaf": 3}) == {"s": {"b": 2}, "leaf": 3} and merge() == {}


def test_ros_arguments_inside_ros_args_only() -> None:
    argv = [
        "exe",
        "-p",
        "not:=ros",
        "--ros-args",
        "--param",
        "a:=1",
        "-r",
        "x:=y",
        "--",
        "--params-file",
        "no",
        "--ros-args",
        "--params-file",
        "b.yaml",
        "-p",
    ]
    assert ros_arguments(argv) == [
        ("--param", "a:=1"),
        ("-r", "x:=y"),
        ("--params-file", "b.yaml"),
        ("-p", None),
    ]
    with pytest.raises(ConfigError, match="-p: a value must follow it"):
        check_ros_arguments(argv[:-3] + ["-p"])
