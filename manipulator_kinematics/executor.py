"""How every process of the package serves its node: rclpy's public executors, one way to spin and
stop, and no exception leaving a callback.

:func:`spin` adds the node to an executor chosen by name (:data:`EXECUTORS`; ``MK_EXECUTOR`` in
the environment, default ``events``) and serves it until its context shuts down (rclpy's
SIGINT/SIGTERM handlers do that, see ``node_util.run``) or until a condition holds. Before that
it wraps the callback of every subscription, timer and service of the node with :func:`guarded`,
so a failing callback is logged (throttled) and the node keeps serving, without each node having
to remember it. Entities created after :func:`spin` started are not wrapped: our nodes create
everything in their constructors.

``events`` is rclpy's ``rclpy.experimental.EventsExecutor`` (C++), the cheapest per message;
``single`` is ``SingleThreadedExecutor`` (about twice its CPU per message). ``events`` also hands
a backlog queued on several topics over in the order it arrived; ``single`` takes one message of
each ready topic in turn. Two traps of EventsExecutor in rclpy 7.1.6, worked around here and
nowhere else:

* ``spin()`` and ``spin_once()`` without a timeout spin at 100 % CPU, serve nothing and ignore
  SIGINT, and so does any timeout above about 7.3e9 s (a deadline that overflows int64 ns): it is
  spun in finite slices (:data:`SLICE`), each ended early by the context's shutdown;
* a subscription callback taking ``(msg, info)`` is never called: every message raises
  ``SystemError: null argument to internal routine`` from the executor. :func:`spin` refuses such
  a node up front under ``events``.

A node whose callbacks must run concurrently (every ``plan_path`` server's plan in a callback
group of its own, beside ``solve_ik``) says so with a class attribute ``THREADS = k`` (k >= 2): it is
served by rclpy's ``MultiThreadedExecutor`` with k threads, whatever the executor's name.
"""

from __future__ import annotations

import contextlib
import functools
import inspect
import os
import sys
import traceback
from collections.abc import Callable
from typing import Any

from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.task import Future

from manipulator_kinematics.param_files import ConfigError
from manipulator_kinematics.throttle import ThrottledLog

EXECUTORS: dict[str, Callable[..., Any]] = {"events": EventsExecutor, "single": SingleThreadedExecutor}
DEFAULT_EXECUTOR = "events"
ENVIRONMENT = "MK_EXECUTOR"
# Longest wait of one EventsExecutor slice: far below the overflow, and a shutdown ends it anyway.
SLICE = 3600.0
# How often a failing callback is logged, per entity (and at most ThrottledLog's lines in all).
ERROR_LOG_PERIOD = 2.0
# Characters of an input shown in the log line of a failed callback.
DESCRIPTION_LENGTH = 200


def executor_name(name: str | None = None) -> str:
    """``name``, else ``$MK_EXECUTOR``, else ``events``; ConfigError for an unknown one."""
    name = name or os.environ.get(ENVIRONMENT) or DEFAULT_EXECUTOR
    if name not in EXECUTORS:
        raise ConfigError(f"{ENVIRONMENT}={name!r}: the executor must be one of {', '.join(EXECUTORS)}")
    return name


def spin(
    node: Node,
    executor: str | None = None,
    until: Callable[[], bool] | None = None,
    poll: float = 0.1,
) -> None:
    """Serve ``node`` with the executor named ``executor`` (:func:`executor_name`) until its context
    shuts down or, when given, ``until()`` is true; ``until`` is asked every ``poll`` s.

    Returns normally in both cases. Callbacks run one at a time in the calling thread, except for
    a node with ``THREADS`` (module docstring).
    """
    name = executor_name(executor)
    guard_callbacks(node)
    threads = getattr(node, "THREADS", 0)
    if threads:
        name = "multi"
    elif name == "events":
        with_info = [s.topic_name for s in node.subscriptions if _wants_message_info(s.callback)]
        if with_info:
            raise ValueError(
                f"subscriptions of {', '.join(with_info)} take (msg, info): EventsExecutor of rclpy 7.1.6 "
                f"cannot call them (SystemError); use {ENVIRONMENT}=single"
            )
    if threads:
        executor_ = new_executor(MultiThreadedExecutor, node.context, num_threads=threads)
    else:
        executor_ = new_executor(EXECUTORS[name], node.context)
    if executor_ is None:
        return
    executor_.add_node(node)
    try:
        # A shutdown can land in any wait: rclpy then raises ExternalShutdownException.
        with contextlib.suppress(ExternalShutdownException):
            if until is None and name != "events":
                try:
                    executor_.spin()
                except RuntimeError:
                    # rclpy's spin checks the context, then builds a wait set on it: a shutdown
                    # landing between the two raises RCLError (a RuntimeError) instead.
                    if node.context.ok():
                        raise
                return
            slice_ = SLICE if until is None else poll
            while node.context.ok() and not (until is not None and until()):
                if name == "events":
                    # A fresh future per slice: each call adds a done-callback to the one it gets.
                    executor_.spin_until_future_complete(Future(), timeout_sec=slice_)
                else:
                    # Costs an rcl timer per callback (rclpy's timeout): only with ``until``.
                    executor_.spin_once(timeout_sec=poll)
    finally:
        executor_.shutdown()
        executor_.remove_node(node)


def new_executor(factory: Callable[..., Any], context: Context, **options: Any) -> Any:
    """``factory(context=context, **options)``, or None when the context is (or gets) shut down
    first: a signal ends the process before its spin, and that is no failure.

    rclpy 7.1.6's executors fail on a shut-down context (RCLError) half-built: ``Executor.__del__``
    then reads ``_sigint_gc``, which ``__init__`` sets last, and ``SignalHandlerGuardCondition``'s
    reads a handle it never got, so collecting them prints "Exception ignored ... AttributeError"
    with a traceback (ros2/rclpy#1178 declined the guard). Those messages, and only while
    building, are dropped here.
    """
    if not context.ok():
        return None
    hook = sys.unraisablehook
    sys.unraisablehook = functools.partial(_drop_half_built, hook)
    try:
        return factory(context=context, **options)
    except RuntimeError:
        if context.ok():
            raise
        return None
    finally:
        sys.unraisablehook = hook


# The finalizers of rclpy 7.1.6 that fail on an object whose __init__ failed.
_HALF_BUILT = frozenset({"Executor.__del__", "SignalHandlerGuardCondition.__del__"})


def _drop_half_built(hook: Callable[[Any], None], unraisable: Any) -> None:
    if not (
        isinstance(unraisable.exc_value, AttributeError)
        and getattr(unraisable.object, "__qualname__", None) in _HALF_BUILT
    ):
        hook(unraisable)


def guard_callbacks(node: Node) -> None:
    """Wrap every subscription, timer and service callback of ``node`` with :func:`guarded`, once.

    ``callback`` is a public attribute of each (a property with a setter for subscriptions, which
    also works out whether the callback takes message info); every executor reads it when it calls.
    """
    log = ThrottledLog(node, ERROR_LOG_PERIOD)
    for sub in node.subscriptions:
        sub.callback = guarded(sub.callback, log, f"subscription to {sub.topic_name}")
    for timer in node.timers:
        timer.callback = guarded(timer.callback, log, f"timer of {timer.timer_period_ns * 1e-9:g} s")
    for srv in node.services:
        srv.callback = guarded(srv.callback, log, f"service {srv.service_name}", _failure_response)


def guarded(
    callback: Callable[..., Any],
    log: ThrottledLog,
    what: str,
    on_error: Callable[..., Any] | None = None,
) -> Callable[..., Any]:
    """``callback`` that never raises an Exception: one is logged through ``log`` (a ThrottledLog,
    one kind per ``what``) with a description of the input, and the call returns ``on_error(error,
    *args)`` (None without it). Signature and name stay the callback's (``functools.wraps``)."""
    if getattr(callback, "guarded", False):
        return callback

    @functools.wraps(callback)
    def call(*args: Any) -> Any:
        try:
            return callback(*args)
        except Exception as error:
            # A callback cut short by the shutdown (publishing on a context shut down under it)
            # is how every node ends, not a failure worth a line.
            if log.node.context.ok():
                log("error", f"{what} failed on {_describe(args)}: {_explain(error)}", kind=what)
            return None if on_error is None else on_error(error, *args)

    call.guarded = True  # type: ignore[attr-defined]
    return call


def _failure_response(error: Exception, request: Any, response: Any) -> Any:
    """The response of a service whose callback failed: ``success`` false and the reason in
    ``message`` where the type has them (our services and std_srvs), else left as constructed."""
    if isinstance(getattr(response, "success", None), bool):
        response.success = False
    if isinstance(getattr(response, "message", None), str):
        response.message = f"internal error: {_explain(error)}"
    return response


def _describe(args: tuple[Any, ...]) -> str:
    """The input of a callback for a log line (the first argument; services: the request)."""
    if not args:
        return "its tick"
    value = args[0]
    if isinstance(value, bytes | bytearray | memoryview):
        data = bytes(value)
        return f"{len(data)} bytes {data[:48].hex()}{'...' if len(data) > 48 else ''}"
    text = repr(value)
    return text if len(text) <= DESCRIPTION_LENGTH else f"{text[:DESCRIPTION_LENGTH]}..."


def _explain(error: Exception) -> str:
    frames = traceback.extract_tb(error.__traceback__)
    where = f" (at {frames[-1].filename}:{frames[-1].lineno} in {frames[-1].name})" if frames else ""
    return f"{type(error).__name__}: {error}{where}"


def _wants_message_info(callback: Callable[..., Any]) -> bool:
    """Whether rclpy hands ``callback`` (msg, info): rclpy's own test, on the public signature."""
    signature = inspect.signature(callback)
    try:
        signature.bind(object())
        return False
    except TypeError:
        return True
