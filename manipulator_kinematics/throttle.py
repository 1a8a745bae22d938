"""ThrottledLog: log lines of a node that stay few whatever its inputs say."""

from __future__ import annotations

import re

from rclpy.node import Node

# Lines per period in all: 1 kHz of inputs each rejected for a different reason (a joint or frame
# name of their own) must not flood the log, nor fill memory with kinds.
MAX_LINES = 10


class ThrottledLog:
    """Logs each kind of message at most once per ``period`` seconds of the node's clock, and at
    most ``max_lines`` lines per ``period`` in all.

    The kind is the caller's ``kind``, else the text with its numbers left out (so rejections
    that differ only in their numbers are one kind; rclpy's own throttle is per call site, so
    different reasons logged from one place would hide each other). A line logged after some
    were held back says how many. Only the kinds logged within the last period are remembered:
    at most ``max_lines``.
    """

    _NUMBER = re.compile(r"[-+]?\d[\d.eE+-]*")

    def __init__(self, node: Node, period: float, max_lines: int = MAX_LINES) -> None:
        self.node = node
        self._period_ns = int(period * 1e9)
        self._max_lines = max_lines
        self._last: dict[str, int] = {}
        self._suppressed = 0

    def __call__(self, severity: str, text: str, kind: str | None = None) -> None:
        """``severity`` is a logger method name: "info", "warning" or "error"."""
        kind = self._NUMBER.sub("#", text) if kind is None else kind
        now = self.node.get_clock().now().nanoseconds
        last = self._last.get(kind)
        if last is not None and now - last < self._period_ns:
            self._suppressed += 1
            return
        if len(self._last) >= self._max_lines:
            self._last = {k: t for k, t in self._last.items() if now - t < self._period_ns}
            if len(self._last) >= self._max_lines:
                self._suppressed += 1
                return
        self._last[kind] = now
        if self._suppressed:
            text = f"{text} ({self._suppressed} more held back since the previous line)"
            self._suppressed = 0
        # One call site per severity: rclpy refuses a call site that changes its severity.
        logger = self.node.get_logger()
        if severity == "error":
            logger.error(text)
        elif severity == "warning":
            logger.warning(text)
        else:
            logger.info(text)
