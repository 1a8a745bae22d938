"""A lean replacement for rclpy's SingleThreadedExecutor for nodes that must keep up with 1 kHz.

rclpy's executor rebuilds its wait set from every node, callback group and entity, then wraps each
callback in a Task (a coroutine) on every wake-up: about 0.2-0.3 ms of Python per message on our
2-core machines, more than the kinematics. At 1 kHz input that alone keeps a core a quarter busy,
so a node falls behind when the machine is loaded and its keep-last queue starts dropping.

:func:`spin` waits in rcl on plain wait sets and serves every entity a node of this package has:
subscriptions (every queued message of the ready ones in one pass, so a node that fell behind
catches up at once, handed over in the order they were sent across topics), timers, services
(the node's own and the parameter services ``ros2 param`` talks to) and waitables (the QoS event
handlers rclpy attaches to publishers and subscriptions). rcl needs a wait set filled anew for
every wait, and a node has a dozen services and event handlers that are rarely ready, which would
double the cost of each wake-up for a message. So the data path (subscriptions and timers) waits
in the calling thread and everything else in a second thread; a lock runs the callbacks one at a
time, as a SingleThreadedExecutor (or one mutually exclusive callback group) does.

Limits, checked or documented: the set of entities is the node's at the start of :func:`spin`
(our nodes create everything in their constructors); clients and guard conditions are not
served, so a node that has them is refused (use rclpy's executor for it); callbacks must be plain
functions, not coroutines.
"""

from __future__ import annotations

import contextlib
import inspect
import threading
from collections.abc import Sequence
from typing import Any

from rclpy.context import Context
from rclpy.executors import ExternalShutdownException
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerGuardCondition
from rclpy.waitable import NumberOfEntities


def spin(node: Node) -> None:
    """Serve ``node`` until its context shuts down: SIGINT/SIGTERM (rclpy's handlers) or a call of
    ``shutdown()`` on the context from any thread.

    Raises ExternalShutdownException then, like rclpy's executors; an exception raised by a
    callback ends the spin and is raised here.
    """
    subscriptions, timers = list(node.subscriptions), list(node.timers)
    services, waitables = list(node.services), list(node.waitables)
    if next(node.clients, None) is not None or next(node.guards, None) is not None:
        raise ValueError(f"node {node.get_name()!r} has clients or guard conditions: use an rclpy executor")
    coroutines = [e for e in (*subscriptions, *timers, *services) if inspect.iscoroutinefunction(e.callback)]
    if coroutines:
        raise ValueError(f"coroutine callbacks need an rclpy executor: {coroutines}")
    # A subscription's event handlers wait on the DDS reader's status condition, which a message
    # in the reader's queue triggers: waited on in another thread than the one that takes the
    # message, they would wake that thread again and again until it is taken.
    reader_events = {id(handler) for s in subscriptions for handler in s.event_handlers}
    lock = threading.Lock()
    data = _Loop(node.context, lock, subscriptions=subscriptions, timers=timers,
                 waitables=[w for w in waitables if id(w) in reader_events])
    rest = _Loop(node.context, lock, services=services,
                 waitables=[w for w in waitables if id(w) not in reader_events])
    helper = threading.Thread(target=rest.run, name=f"{node.get_name()}_services", daemon=True)
    # Either loop ending (shutdown, or a callback's exception) ends the other.
    data.partner, rest.partner = rest, data
    helper.start()
    try:
        data.run()
    finally:
        rest.stop()
        helper.join()
    for loop in (data, rest):
        if loop.error is not None:
            raise loop.error
    raise ExternalShutdownException()


class _Loop:
    """One wait set over some of a node's entities, served by the thread that calls :meth:`run`."""

    def __init__(
        self,
        context: Context,
        lock: threading.Lock,
        subscriptions: Sequence[Any] = (),
        timers: Sequence[Any] = (),
        services: Sequence[Any] = (),
        waitables: Sequence[Any] = (),
    ) -> None:
        self.context, self.lock = context, lock
        self.entities = (subscriptions, timers, services, waitables)
        # A guard condition can be in one wait set at a time (rmw_fastrtps): each loop has its own.
        self.guards = (SignalHandlerGuardCondition(context), GuardCondition(None, None, context))
        self.partner: _Loop | None = None
        self.error: BaseException | None = None
        self._stopping = False
        self._guards_lock = threading.Lock()  # stop() may come from any thread, even after run()
        context.on_shutdown(self.stop)

    def stop(self) -> None:
        """End :meth:`run` soon, from any thread."""
        with self._guards_lock:
            if not self._stopping:
                self._stopping = True
                self.guards[1].trigger()

    def run(self) -> None:
        try:
            self._serve()
        except BaseException as error:
            # rcl refuses a wait set or a wait on a context shut down meanwhile: that is the end
            # of the spin, not an error.
            if self.context.ok():
                self.error = error
        finally:
            with self._guards_lock:
                self._stopping = True
                for guard in self.guards:
                    guard.destroy()
            if self.partner is not None:
                self.partner.stop()

    def _serve(self) -> None:
        subscriptions, timers, services, waitables = self.entities
        count = NumberOfEntities(len(subscriptions), len(self.guards), len(timers), 0, len(services))
        for waitable in waitables:
            count += waitable.get_num_entities()
        wait_set = _rclpy.WaitSet(
            count.num_subscriptions,
            count.num_guard_conditions,
            count.num_timers,
            count.num_clients,
            count.num_services,
            count.num_events,
            self.context.handle,
        )
        by_pointer = {entity.handle.pointer: entity for entity in (*subscriptions, *timers, *services)}
        lock = self.lock
        # Handles stay entered while serving, so nothing is destroyed under a wait (rclpy's rule).
        with contextlib.ExitStack() as held:
            for entity in (*subscriptions, *timers, *services, *self.guards):
                held.enter_context(entity.handle)
            for waitable in waitables:
                held.enter_context(waitable)
            while self.context.ok() and not self._stopping:
                wait_set.clear_entities()
                for subscription in subscriptions:
                    wait_set.add_subscription(subscription.handle)
                for timer in timers:
                    wait_set.add_timer(timer.handle)
                for service in services:
                    wait_set.add_service(service.handle)
                for guard in self.guards:
                    wait_set.add_guard_condition(guard.handle)
                for waitable in waitables:
                    waitable.add_to_wait_set(wait_set)
                wait_set.wait(-1)  # rcl bounds the wait by the timers; a guard ends it
                if not self.context.ok() or self._stopping:
                    return
                with lock:
                    # Only the kinds this loop has: each query costs as much as a small callback.
                    if subscriptions:
                        _take_messages([by_pointer[p] for p in wait_set.get_ready_entities("subscription")])
                    if timers:
                        for pointer in wait_set.get_ready_entities("timer"):
                            timer = by_pointer[pointer]
                            timer.handle.call_timer()
                            timer.callback()
                    if services:
                        for pointer in wait_set.get_ready_entities("service"):
                            _serve(by_pointer[pointer])
                    for waitable in waitables:
                        if waitable.is_ready(wait_set):
                            _run_to_completion(waitable.execute(waitable.take_data()))


def _take_messages(ready: list[Any]) -> None:
    """Every queued message of the ready subscriptions, to their callbacks in the order they were
    sent (source timestamp): a node that fell behind sees its inputs interleaved as they came,
    so a message of one topic is never handled ahead of an older one of another."""
    taken = []
    for subscription in ready:
        handle, msg_type, raw = subscription.handle, subscription.msg_type, subscription.raw
        while (item := handle.take_message(msg_type, raw)) is not None:
            taken.append((item[1]["source_timestamp"], len(taken), subscription, item))
    if len(ready) > 1:
        taken.sort()  # by source timestamp, then take order (never reaches the subscriptions)
    for _, _, subscription, (message, info) in taken:
        if subscription._callback_type is subscription.CallbackType.MessageOnly:
            subscription.callback(message)
        else:
            subscription.callback(message, info)


def _serve(service: Any) -> None:
    request, header = service.handle.service_take_request(service.srv_type.Request)
    if header is not None:
        service.send_response(service.callback(request, service.srv_type.Response()), header)


def _run_to_completion(coroutine: Any) -> None:
    """Drive a waitable's ``execute`` coroutine; rclpy's event handlers never really suspend."""
    try:
        coroutine.send(None)
    except StopIteration:
        return
    coroutine.close()
    raise RuntimeError("a waitable suspended: it needs an rclpy executor")
