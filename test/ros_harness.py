"""Real nodes over real DDS for integration tests: start console scripts as processes, talk
to them from an in-test node, and wait on conditions with timeouts (never fixed sleeps)."""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Self

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from manipulator_kinematics.node_util import console_script

REPO = Path(__file__).resolve().parent.parent


class NodeProcess:
    """A node started as its console script; ``stop()`` ends it with SIGINT and returns its log."""

    def __init__(self, exe: str, *ros_args: str, args: tuple[str, ...] = ()) -> None:
        self._log = tempfile.NamedTemporaryFile("w+", prefix=f"{exe}-", suffix=".log", delete=False)  # noqa: SIM115
        command = [console_script(exe), *args]
        if ros_args:
            command += ["--ros-args", *ros_args]
        self.process = subprocess.Popen(
            command, stdout=self._log, stderr=subprocess.STDOUT, env=os.environ.copy()
        )

    def alive(self) -> bool:
        return self.process.poll() is None

    def log(self) -> str:
        self._log.flush()
        return Path(self._log.name).read_text(encoding="utf-8", errors="replace")

    def stop(self, timeout: float = 10.0) -> str:
        if self.alive():
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout)
        text = self.log()
        self._log.close()
        os.unlink(self._log.name)
        return text

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


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

    def call(self, client, request, timeout: float, what: str = "service response",
             resend_after: float = 2.0):
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
