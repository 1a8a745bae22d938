"""Helpers shared by every rclpy node of the package: start-up, parameters, clean shutdown.

Nodes are created with ``automatically_declare_parameters_from_overrides`` so a machine
description given by ``--ros-args --params-file config/<machine>.yaml`` arrives whole, whatever
its keys; :func:`machine_parameters` turns it back into the nested dict the numpy cores take.
"""
from __future__ import annotations

import signal
import sys
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from manipulator_kinematics.params import ConfigError, config_path, load_parameters, unflatten


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
    given = unflatten(
        {name: p.value for name, p in node.get_parameters_by_prefix(prefix).items()}
    )
    return _merge(defaults, given)


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in over.items():
        out[key] = _merge(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def run(node_factory: Callable[[], Node], args: Sequence[str] | None = None) -> int:
    """Entry point body of every console script: init, build, spin until SIGINT/SIGTERM.

    A machine description that fails validation ends the process with its message and exit
    code 2 (nothing to serve); everything after start-up is handled inside the node.
    """
    rclpy.init(args=list(args) if args is not None else sys.argv)
    # SIGTERM (what launch and test harnesses send) ends the spin like Ctrl-C does.
    signal.signal(signal.SIGTERM, lambda *_: rclpy.try_shutdown())
    node = None
    try:
        node = node_factory()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except ConfigError as error:
        print(f"configuration error: {error}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
