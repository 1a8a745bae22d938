"""SIGINT and SIGTERM end every executable of the package with exit 0 and no traceback, at any moment.

Python's defaults do neither: SIGINT raises KeyboardInterrupt wherever the main thread is (a
traceback, then exit -2) and SIGTERM kills the process (-15); rclpy replaces them only from
``rclpy.init`` on, after a second or more of imports. So the ``__init__`` of every top-level
package with console scripts calls :func:`install_for` with their names: the first code of ours a
console script runs (``from scara_kinematics.nodes import forward`` runs
``scara_kinematics/__init__.py`` first). A process then has two phases:

* start-up (imports, arguments, reading a bag; nothing to clean up yet; all of a batch tool's
  run, the plot tools, ``pump_boom_regions`` and ``excavator_demo`` included): a signal ends the
  process at once, exit 0, with one line on stderr, after ending the child processes it started
  (:func:`adopt`: SIGTERM, then SIGKILL for what still runs after :data:`CHILD_GRACE`);
* from :func:`hold` on (called just before ``rclpy.init``): a signal is only recorded
  (:func:`requested`, :func:`on_request`) and the program ends itself. rclpy's handlers, when
  ``rclpy.init`` installs them, shut the context down first and then call this handler (they
  chain to the Python handler found at init), so a spin ends; programs that take no handlers from
  rclpy (mk_record, mk_replay) poll :func:`requested` or register with :func:`on_request`.

At exit the two signals are ignored: the interpreter's finalization puts back the default
handlers of every signal with a Python handler (not of ignored ones), and a signal then would
end the process with -2 or -15 after all. Only the interpreter's own start-up, before the
console script's first import, is outside this module's reach (the operating system's defaults
apply: 27-549 ms from exec in 50 runs at a load average of 8-13 on 2 cores).

No import beyond the standard library's ``atexit``, ``contextlib``, ``os``, ``signal``, ``sys``
and ``time``: this runs before them.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import signal
import sys
import time
from collections.abc import Callable, Iterator
from typing import Protocol

SIGNALS = (signal.SIGINT, signal.SIGTERM)

_holding = False
_starting = False
_received: int | None = None
_callbacks: list[Callable[[], None]] = []
#: Seconds a child gets to end on SIGTERM before SIGKILL: the whole stop stays under 2 s.
CHILD_GRACE = 1.2


class Child(Protocol):
    """What :func:`adopt` needs of a child process (a ``subprocess.Popen``)."""

    pid: int

    def poll(self) -> int | None: ...


_children: list[Child] = []


def install_for(*executables: str) -> None:
    """:func:`install` when this process runs as one of ``executables`` (the console script the
    module provides): a module imported by a test or a library user leaves the signals alone."""
    program = getattr(sys.modules.get("__main__"), "__file__", None) or ""
    if os.path.basename(program) in executables:
        install()


def install() -> None:
    """This module's handler for SIGINT and SIGTERM (start-up phase until :func:`hold`), and both
    ignored from the last exit handler on."""
    for signum in SIGNALS:
        signal.signal(signum, _on_signal)
    atexit.register(_ignore_signals)  # registered first, called last


def hold() -> None:
    """From now on a signal is only recorded: the program shuts down itself. Installs the handler
    if :func:`install` has not (an entry point called in-process)."""
    global _holding
    if signal.getsignal(signal.SIGTERM) is not _on_signal:
        install()
    _holding = True


def requested() -> bool:
    """Whether SIGINT or SIGTERM has arrived."""
    return _received is not None


def on_request(callback: Callable[[], None]) -> None:
    """Call ``callback`` (in the main thread) when a signal arrives; at once if one already has."""
    _callbacks.append(callback)
    if requested():
        callback()


def adopt(child: Child) -> Child:
    """``child`` is ended with this process when a signal ends it in the start-up phase (a tool
    that starts nodes: nothing of it may outlive it). Returns ``child``. Start and adopt it in a
    :func:`starting` block."""
    _children.append(child)
    return child


@contextlib.contextmanager
def starting() -> Iterator[None]:
    """A block that starts children and adopts them: a signal arriving inside it (after the
    fork, before :func:`adopt`) ends this process only when the block ends, so the child it
    started is ended too instead of outliving it."""
    global _starting
    _starting = True
    try:
        yield
    finally:
        _starting = False
        if _received is not None and not _holding:
            _end(_received)


def _end_children() -> None:
    """SIGTERM to every adopted child still running, SIGKILL to those left after CHILD_GRACE."""
    running = [child for child in _children if child.poll() is None]
    for child in running:
        _kill(child.pid, signal.SIGTERM)
    deadline = time.monotonic() + CHILD_GRACE
    while running and time.monotonic() < deadline:
        time.sleep(0.02)
        running = [child for child in running if child.poll() is None]
    for child in running:
        _kill(child.pid, signal.SIGKILL)
        child.poll()


def _kill(pid: int, signum: int) -> None:
    with contextlib.suppress(ProcessLookupError):  # ended (and reaped) meanwhile
        os.kill(pid, signum)


def _on_signal(signum: int, frame: object) -> None:
    global _received
    _received = signum
    if not _holding:
        if not _starting:  # else the end of the starting() block ends the process
            _end(signum)
        return
    for callback in _callbacks:
        callback()


def _end(signum: int) -> None:
    """The start-up phase's ending: one line, the children ended, exit 0."""
    # A second signal (Ctrl-C twice, launch's escalation) may run the handler again while the
    # first waits for the children: one line, one ending.
    _ignore_signals()
    # Nothing to clean up but the children; os.write bypasses Python's buffers, which the
    # interrupted main thread may be holding.
    name = os.path.basename(getattr(sys.modules.get("__main__"), "__file__", None) or sys.argv[0])
    os.write(2, f"{name}: stopped by {signal.Signals(signum).name}\n".encode())
    _end_children()
    os._exit(0)


def _ignore_signals() -> None:
    for signum in SIGNALS:
        signal.signal(signum, signal.SIG_IGN)
