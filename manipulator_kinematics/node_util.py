"""Helpers shared by every rclpy node of the package: start-up, parameters, clean shutdown.

Nodes are created with ``automatically_declare_parameters_from_overrides`` so a machine
description given by ``--ros-args --params-file config/<machine>.yaml`` arrives whole, whatever
its keys (:mod:`manipulator_kinematics.nodes.base` validates it). Parameters are read at
start-up: :func:`run` refuses a run-time change with that reason (:func:`refuse_runtime_changes`)
unless the node applies changes itself and opts out.
"""

from __future__ import annotations

import shutil
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from manipulator_kinematics import compiled, executor, stopping
from manipulator_kinematics.param_files import ConfigError, check_ros_arguments
from manipulator_kinematics.throttle import ThrottledLog

__all__ = [
    "ThrottledLog",
    "console_script",
    "make_node",
    "param",
    "refuse_runtime_changes",
    "run",
]


STARTUP_ONLY = "parameters are read at start-up"


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


def param(
    node: Node,
    name: str,
    default: Any,
    description: str = "",
    bounds: tuple[float, float] | None = None,
    constraints: str = "",
) -> Any:
    """Value of parameter ``name``, declaring it with ``default`` when no override exists; either
    way it gets a read-only descriptor, so ``ros2 param describe`` shows it as a start-up setting,
    with ``bounds`` (min, max) as its range when it is a single number and ``constraints`` (what
    values it takes) after that."""
    given = node.get_parameter(name) if node.has_parameter(name) else None
    kind = given.type_ if given is not None else Parameter.Type.from_parameter_value(default)
    descriptor = ParameterDescriptor(
        description=description,
        type=kind.value,
        read_only=True,
        additional_constraints=f"{STARTUP_ONLY}; {constraints}" if constraints else STARTUP_ONLY,
    )
    if bounds is not None and kind == Parameter.Type.DOUBLE:
        descriptor.floating_point_range = [FloatingPointRange(from_value=bounds[0], to_value=bounds[1])]
    elif bounds is not None and kind == Parameter.Type.INTEGER:
        descriptor.integer_range = [IntegerRange(from_value=int(bounds[0]), to_value=int(bounds[1]))]
    if given is not None:
        node.set_descriptor(name, descriptor)
        return given.value
    return node.declare_parameter(name, default, descriptor).value


def run(
    node_factory: Callable[[], Node],
    args: Sequence[str] | None = None,
    *,
    refuse_parameter_changes: bool = True,
) -> int:
    """Entry point body of every console script: init, build, spin until SIGINT/SIGTERM, exit 0.

    The node is spun by :func:`manipulator_kinematics.executor.spin` (executor from
    ``MK_EXECUTOR``, default ``events``), which also keeps every callback's exceptions inside it.
    A node that applies ``ros2 param set`` itself passes ``refuse_parameter_changes=False``;
    every other gets :func:`refuse_runtime_changes`. A machine description or setting that fails
    validation ends the process with its message and exit code 2 (nothing to serve).
    """
    # A signal from here on is only recorded (manipulator_kinematics.stopping): rclpy's handlers,
    # installed by init, shut the context down, which ends the spin, and then call ours.
    stopping.hold()
    argv = list(args) if args is not None else sys.argv
    try:
        check_ros_arguments(argv)
        rclpy.init(args=argv)
    except ConfigError as error:
        print(f"invalid arguments: {error}", file=sys.stderr)
        return 2
    except Exception as error:  # rcl refused what the check above let through
        print(f"invalid ROS arguments: {str(error).splitlines()[0]}", file=sys.stderr)
        return 2
    node = None
    code = 0
    try:
        if not stopping.requested():  # else: during rclpy.init, before its handlers were in
            name = executor.executor_name()
            node = node_factory()
            if refuse_parameter_changes:
                refuse_runtime_changes(node)
            executor.spin(node, name)
    except ConfigError as error:
        print(f"configuration error: {error}", file=sys.stderr)
        code = 2
    except Exception:
        # A signal shuts the context down from rclpy's own thread, also while the node is being
        # built: rclpy then raises RCLError or RuntimeError from wherever the main thread was.
        if not stopping.requested():
            raise
    finally:
        _shut_down(node)
    # rclpy is shut down: a kernel still loading (seconds on a cold machine) is not waited for.
    compiled.exit_now_if_loading(code)
    return code


def _shut_down(node: Node | None) -> None:
    """Destroy ``node`` and shut rclpy down; a signal's shutdown racing either is no failure."""
    try:
        if node is not None:
            node.destroy_node()
    except Exception:
        if not stopping.requested():
            raise
    finally:
        rclpy.try_shutdown()


def refuse_runtime_changes(node: Node) -> None:
    """Refuse every ``ros2 param set`` on ``node`` with the reason: its parameters are read at
    start-up. Parameters declared later (not yet known to the node) are let through."""

    def on_set(parameters: list[Parameter]) -> SetParametersResult:
        known = [p.name for p in parameters if node.has_parameter(p.name)]
        if known:
            return SetParametersResult(
                successful=False, reason=f"{STARTUP_ONLY}: restart the node to change {', '.join(known)}"
            )
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)
