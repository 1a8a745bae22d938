"""Helpers shared by every rclpy node of the package: start-up, parameters, clean shutdown.

Nodes are created with ``automatically_declare_parameters_from_overrides`` so a machine
description given by ``--ros-args --params-file config/<machine>.yaml`` arrives whole, whatever
its keys; :func:`machine_parameters` turns it back into the nested dict the numpy cores take.
"""

from __future__ import annotations

import re
import shutil
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from manipulator_kinematics import spin
from manipulator_kinematics.params import ConfigError, config_path, flatten, load_parameters, unflatten


def console_script(name: str) -> str:
    """Path of a console script of the package: beside this interpreter (the venv), else on PATH."""
    beside = Path(sys.executable).parent / name
    found = str(beside) if beside.exists() else shutil.which(name)
    if not found:
        raise FileNotFoundError(
            f"console script {name!r} not found; run the set-up command (scripts/bootstrap.sh)"
        )
    return found


def make_node(name: str) -> Node:
    """A node that accepts every parameter given on the command line or in a params file."""
    return Node(name, automatically_declare_parameters_from_overrides=True)


def param(node: Node, name: str, default: Any) -> Any:
    """Value of parameter ``name``, declaring it with ``default`` when no override exists."""
    if node.has_parameter(name):
        return node.get_parameter(name).value
    return node.declare_parameter(name, default).value


def machine_parameters(node: Node, prefix: str, default_file: str) -> dict[str, Any]:
    """Nested machine description under ``prefix`` (e.g. ``excavator``).

    Parameters given to the node win; keys it was not given come from the package's default
    config file, so ``-p excavator.boom.length:=6.0`` changes one value of the default machine.
    """
    defaults = load_parameters(config_path(default_file), node.get_name()).get(prefix, {})
    given = unflatten({name: p.value for name, p in node.get_parameters_by_prefix(prefix).items()})
    return _merge(defaults, given)


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in over.items():
        both_sections = isinstance(value, dict) and isinstance(out.get(key), dict)
        out[key] = _merge(out[key], value) if both_sections else value
    return out


def run(node_factory: Callable[[], Node], args: Sequence[str] | None = None) -> int:
    """Entry point body of every console script: init, build, spin until SIGINT/SIGTERM.

    A machine description that fails validation ends the process with its message and exit
    code 2 (nothing to serve); everything after start-up is handled inside the node.
    """
    # rclpy's own handlers (SignalHandlerOptions.ALL) turn SIGINT and SIGTERM into a shutdown of
    # the context, which ends the spin below.
    rclpy.init(args=list(args) if args is not None else sys.argv)
    node = None
    try:
        node = node_factory()
        spin.spin(node)
    except ConfigError as error:
        print(f"configuration error: {error}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # A signal can shut the context down while the executor builds its wait set or takes a
        # message; rclpy then raises RCLError or RuntimeError instead of ExternalShutdownException.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def node_parameters(node: Node, default_file: str, section: str) -> dict[str, Any]:
    """Settings of a node: every key of ``section`` in the package's ``default_file``, declared on
    the node with the file's value as default, so values given to the node win and the file stays
    the one place where defaults live. Keys are dotted (``topics.bucket_pose``)."""
    defaults = flatten(load_parameters(config_path(default_file), section))
    return {name: param(node, name, value) for name, value in defaults.items()}


class ThrottledLog:
    """Logs each kind of message at most once per ``period`` seconds of the node's clock.

    Messages that differ only in their numbers are of one kind. rclpy's own throttle is per call
    site, so different reasons for rejecting an input, logged from one place, would hide each other.
    """

    _NUMBER = re.compile(r"[-+]?\d[\d.eE+-]*")

    def __init__(self, node: Node, period: float) -> None:
        self._node = node
        self._period_ns = int(period * 1e9)
        self._last: dict[str, int] = {}

    def __call__(self, severity: str, text: str) -> None:
        """``severity`` is a logger method name: "info", "warning" or "error"."""
        kind = self._NUMBER.sub("#", text)
        now = self._node.get_clock().now().nanoseconds
        last = self._last.get(kind)
        if last is not None and now - last < self._period_ns:
            return
        self._last[kind] = now
        # One call site per severity: rclpy refuses a call site that changes its severity.
        logger = self._node.get_logger()
        if severity == "error":
            logger.error(text)
        elif severity == "warning":
            logger.warning(text)
        else:
            logger.info(text)
