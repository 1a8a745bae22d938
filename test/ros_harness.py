"""Real nodes over real DDS for integration tests: start console scripts as processes, talk
to them from an in-test node, and wait on conditions with timeouts (never fixed sleeps)."""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Self

import rclpy
import yaml
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from manipulator_kinematics.node_util import console_script
from manipulator_kinematics_interfaces.srv import SolveFK, SolveIK

REPO = Path(__file__).resolve().parent.parent
#: Set by conftest.py to a directory of this test run, removed (and checked empty) at its end.
SCRATCH_ENV = "MK_TEST_SCRATCH"


def scratch_dir() -> Path:
    """Where the harness keeps a process's log and params file while it runs: the test run's own
    directory (conftest.py), else the system's temporary directory."""
    return Path(os.environ.get(SCRATCH_ENV) or tempfile.gettempdir())


# Every NodeProcess not stopped yet, held so that stop_all() can still stop it.
_RUNNING: set[NodeProcess] = set()


def stop_all() -> list[str]:
    """Stop every process a test left running (and delete its files); their commands."""
    left = sorted(_RUNNING, key=lambda p: p.process.pid)
    for process in left:
        process.stop()
    return [" ".join(map(str, process.process.args)) for process in left]


class NodeProcess:
    """A node started as its console script; ``stop()`` ends it with SIGINT, deletes its files and
    returns its log.

    ``params``: a ROS parameters document (``{"/ns/node": {"ros__parameters": {...}}}``) written
    to a file given after ``ros_args``' own ``--params-file``s (a later file wins).
    """

    def __init__(
        self, exe: str, *ros_args: str, args: tuple[str, ...] = (), params: dict[str, Any] | None = None
    ) -> None:
        self._files: list[Path] = []
        self._text: str | None = None
        self._log = tempfile.NamedTemporaryFile(  # noqa: SIM115 - closed and deleted by stop()
            "w+", prefix=f"{exe}-", suffix=".log", dir=scratch_dir(), delete=False
        )
        self._files.append(Path(self._log.name))
        if params is not None:
            with tempfile.NamedTemporaryFile(
                "w", prefix=f"{exe}-", suffix=".yaml", dir=scratch_dir(), delete=False
            ) as file:
                self._files.append(Path(file.name))
                yaml.safe_dump(params, file)
            ros_args = (*ros_args, "--params-file", file.name)
        command = [console_script(exe), *args]
        if ros_args:
            command += ["--ros-args", *ros_args]
        self.process = subprocess.Popen(
            command, stdout=self._log, stderr=subprocess.STDOUT, env=os.environ.copy()
        )
        _RUNNING.add(self)

    def alive(self) -> bool:
        return self.process.poll() is None

    def log(self) -> str:
        if self._text is not None:
            return self._text
        self._log.flush()
        return Path(self._log.name).read_text(encoding="utf-8", errors="replace")

    def stop(self, timeout: float = 10.0) -> str:
        """End the process (SIGINT, then SIGKILL after ``timeout``) and delete its files; the log.
        Stopping again returns the same log."""
        if self._text is not None:
            return self._text
        try:
            if self.alive():
                self.process.send_signal(signal.SIGINT)
                try:
                    self.process.wait(timeout)
                except subprocess.TimeoutExpired:
                    self.process.kill()
                    self.process.wait(timeout)
            self._text = self.log()
        finally:
            self._log.close()
            for path in self._files:
                path.unlink(missing_ok=True)
            _RUNNING.discard(self)
        return self._text

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


#: For a test that checks an output for every input it sends. The nodes' default
#: input_reliability is best_effort (docs/architecture.md, "Input QoS"): it hears every kind of
#: publisher, but a message sent right after the publisher matched the node's reader (before the
#: reader knows the writer) or on a loaded machine can be lost, and the test would wait for it.
RELIABLE_INPUTS = ("-p", "input_reliability:=reliable")

#: rclpy's warning when rmw_fastrtps drops a response to a client it has not matched yet; not the
#: node's fault, and ``Probe.call`` re-sends the request.
DROPPED_RESPONSE = "failed to send response (timeout): client will not receive response"


def runtime_warnings(log: str) -> list[str]:
    """The ``RuntimeWarning`` lines of a node's log (numpy's overflow or invalid value, say),
    a dropped response (``DROPPED_RESPONSE``) left out."""
    return [line for line in log.splitlines() if "RuntimeWarning" in line and DROPPED_RESPONSE not in line]


#: The IK/FK services every serial machine's IK server offers.
IK_FK = ((SolveIK, "solve_ik"), (SolveFK, "solve_fk"))


def start_with_services(
    probe: Probe,
    exe: str,
    *ros_args: str,
    services: Sequence[tuple[type, str]],
    timeout: float,
    namespace: str = "",
) -> tuple[NodeProcess, list[Any]]:
    """Start ``exe`` and wait until it serves every (type, name) of ``services`` to the probe;
    the process and one client per service. A node that dies or never serves is stopped and the
    failure shows its log."""
    process = NodeProcess(exe, *ros_args)
    clients = [
        probe.node.create_client(kind, f"{namespace}/{name}" if namespace else name)
        for kind, name in services
    ]
    try:
        probe.wait_until(
            lambda: all(c.service_is_ready() for c in clients) or not process.alive(),
            timeout,
            " and ".join(name for _, name in services),
        )
        assert process.alive(), process.log()
    except BaseException:
        print(process.stop())
        raise
    return process, clients


class Probe:
    """The test's own node and executor; ``wait_until`` spins until a condition holds."""

    def __init__(self, name: str = "test_probe") -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def wait_until(self, condition: Callable[[], bool], timeout: float, what: str = "condition") -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                raise TimeoutError(f"timed out after {timeout} s waiting for {what}")
            self.executor.spin_once(timeout_sec=0.01)

    def call(
        self, client, request, timeout: float, what: str = "service response", resend_after: float = 2.0
    ):
        """One service round trip, re-sending the request every ``resend_after`` seconds without a reply.

        rmw_fastrtps drops a response when the client's response reader has not matched the server
        within 100 ms ("client will not receive response", ros2/rmw_fastrtps#390 and #467), which
        ``service_is_ready()`` cannot see; on a loaded machine the first request can be lost that way.
        Our services are idempotent, so re-sending is safe; only a server that never answers fails.
        """
        deadline = time.monotonic() + timeout
        while True:
            future = client.call_async(request)
            try:
                self.wait_until(future.done, min(resend_after, max(deadline - time.monotonic(), 0.0)), what)
                return future.result()
            except TimeoutError:
                client.remove_pending_request(future)
                if time.monotonic() >= deadline:
                    raise TimeoutError(f"timed out after {timeout} s waiting for {what}") from None

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)
