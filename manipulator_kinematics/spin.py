"""A lean replacement for rclpy's SingleThreadedExecutor for nodes that must keep up with 1 kHz.

rclpy's executor rebuilds its wait set from every node, callback group and entity, then wraps each
callback in a Task (a coroutine) on every wake-up: about 0.2-0.3 ms of Python per message on our
2-core machines, more than the kinematics. At 1 kHz input that alone keeps a core a quarter busy,
so a node falls behind when the machine is loaded and its keep-last queue starts dropping.

:func:`spin` waits in rcl on the same wait set, built once, and serves every entity a node of
this package has: subscriptions (every queued message of a ready subscription in one pass, so a
node that fell behind catches up at once), timers, services (the node's own and the parameter
services ``ros2 param`` talks to) and waitables (the QoS event handlers rclpy attaches to
publishers and subscriptions). Callbacks run plainly, in the spinning thread, one at a time:
what a SingleThreadedExecutor with one mutually exclusive callback group guarantees too.

Limits, checked or documented: the set of entities is the node's at the start of :func:`spin`
(our nodes create everything in their constructors); clients and guard conditions are not
served, so a node that has them is refused (use rclpy's executor for it); callbacks must be plain
functions, not coroutines.
"""

from __future__ import annotations

import contextlib
import inspect

from rclpy.executors import ExternalShutdownException
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerGuardCondition
from rclpy.waitable import NumberOfEntities


def spin(node: Node) -> None:
    """Serve ``node`` until its context shuts down: SIGINT/SIGTERM (rclpy's handlers) or a call of
    ``shutdown()`` on the context from any thread.

    Raises ExternalShutdownException then, like rclpy's executors.
    """
    subscriptions, timers = list(node.subscriptions), list(node.timers)
    services, waitables = list(node.services), list(node.waitables)
    if next(node.clients, None) is not None or next(node.guards, None) is not None:
        raise ValueError(f"node {node.get_name()!r} has clients or guard conditions: use an rclpy executor")
    callbacks = subscriptions + timers + services
    coroutines = [entity for entity in callbacks if inspect.iscoroutinefunction(entity.callback)]
    if coroutines:
        raise ValueError(f"coroutine callbacks need an rclpy executor: {coroutines}")
    context = node.context
    guards = (SignalHandlerGuardCondition(context), GuardCondition(None, None, context))
    context.on_shutdown(guards[1].trigger)
    count = NumberOfEntities(len(subscriptions), len(guards), len(timers), 0, len(services))
    for waitable in waitables:
        count += waitable.get_num_entities()
    wait_set = _rclpy.WaitSet(
        count.num_subscriptions,
        count.num_guard_conditions,
        count.num_timers,
        count.num_clients,
        count.num_services,
        count.num_events,
        context.handle,
    )
    # Handles stay entered while spinning, so nothing is destroyed under a wait (rclpy's rule).
    with contextlib.ExitStack() as held:
        for guard in guards:
            held.callback(guard.destroy)  # runs last: after the handles are released
        for entity in (*callbacks, *guards):
            held.enter_context(entity.handle)
        for waitable in waitables:
            held.enter_context(waitable)
        by_pointer = {entity.handle.pointer: entity for entity in callbacks}
        while context.ok():
            wait_set.clear_entities()
            for subscription in subscriptions:
                wait_set.add_subscription(subscription.handle)
            for timer in timers:
                wait_set.add_timer(timer.handle)
            for service in services:
                wait_set.add_service(service.handle)
            for guard in guards:
                wait_set.add_guard_condition(guard.handle)
            for waitable in waitables:
                waitable.add_to_wait_set(wait_set)
            wait_set.wait(-1)  # rcl bounds the wait by the timers; a guard ends it at shutdown
            if not context.ok():
                break
            for pointer in wait_set.get_ready_entities("subscription"):
                _take_messages(by_pointer[pointer])
            for pointer in wait_set.get_ready_entities("timer"):
                timer = by_pointer[pointer]
                timer.handle.call_timer()
                timer.callback()
            for pointer in wait_set.get_ready_entities("service"):
                _serve(by_pointer[pointer])
            for waitable in waitables:
                if waitable.is_ready(wait_set):
                    _run_to_completion(waitable.execute(waitable.take_data()))
    raise ExternalShutdownException()


def _take_messages(subscription) -> None:
    handle, msg_type, raw, callback = (
        subscription.handle, subscription.msg_type, subscription.raw, subscription.callback
    )
    with_info = subscription._callback_type is not subscription.CallbackType.MessageOnly
    while (taken := handle.take_message(msg_type, raw)) is not None:
        if with_info:
            callback(*taken)
        else:
            callback(taken[0])


def _serve(service) -> None:
    request, header = service.handle.service_take_request(service.srv_type.Request)
    if header is not None:
        service.send_response(service.callback(request, service.srv_type.Response()), header)


def _run_to_completion(coroutine) -> None:
    """Drive a waitable's ``execute`` coroutine; rclpy's event handlers never really suspend."""
    try:
        coroutine.send(None)
    except StopIteration:
        return
    coroutine.close()
    raise RuntimeError("a waitable suspended: it needs an rclpy executor")
