"""One compiled kernel behind a numpy function: loaded in the background, the numpy path meanwhile.

Every machine's math is plain vectorised numpy on (..., n) arrays, one state being a batch of
one; that path is the reference. Where a user loops over single calls (a node at 1 kHz, an IK
service), numpy's fixed cost per call (about a microsecond per ufunc, hundreds per closed form)
dominates, so the single call runs the same steps as scalar loops compiled by numba, kept in
numba's on-disk cache (``cache=True``: ``__pycache__`` next to the kernel module, or numba's
user-wide cache directory where that is not writable). A test per kernel compares it with the
numpy path (to 1e-12, statuses and selections equal).

:class:`Kernel` loads the kernel module in a thread started by the first call that can use it,
a single call or a batch: once loaded, the kernel's loops serve batches of every size too, into
preallocated outputs (issue #32: numpy's fixed cost made a batch of one cost up to 20x a single
call, and its temporaries cost a fresh process 2-4x per state in a band of sizes;
benchmarks/bench_batch.py). Until it is ready every call takes the numpy path, so a node's first
output never waits for numba.

Exit and signals (issue 28 item 2: a process stops within 2 s at any moment):

* a cold cache (no index of the module in numba's cache, or one older than its source) is
  filled by a child process (``python -c``, the warm function and its sample pickled to it), so
  the compile (5-30 s on 2 cores, the hydraulic family's about 100 s) can be abandoned: the
  child is killed when the process ends (:func:`abandon`, at exit or from
  :func:`manipulator_kinematics.node_util.run`) and ends itself if its parent vanishes; the numpy
  path goes on answering;
* from a warm cache the module is loaded in this process (0.5-1.2 s, up to 5 s on a loaded
  machine: numba's import) by a daemon thread, which a process that ends does not wait for.
  A daemon thread still running Python while the interpreter finalizes is ended inside whatever
  it calls, and in rclpy's handle destructors (its garbage collection) that aborted a signalled
  node (exit -6, c84e331). So where rclpy is imported the process either leaves without
  finalizing (``node_util.run``: ``os._exit`` with its exit code after rclpy's clean shutdown,
  when a load is still running) or, for any other program, waits for the load at exit (an
  ``atexit`` hook, before finalization). A process without rclpy just ends.

The cache is numba's (``cache=True``): ``__pycache__`` beside the kernel module where that is
writable (the editable tree; an install by its owner, e.g. colcon's ``install/``), else numba's
user-wide directory (``~/.cache/numba``, ``$XDG_CACHE_HOME``), or ``NUMBA_CACHE_DIR`` when set.
``scripts/bootstrap.sh`` runs ``scripts/warm_kernels.py`` (run it after ``colcon build`` too),
which compiles every kernel of the package, so a user's first run finds the cache warm
(docs/architecture.md, "Compiled kernels, set-up and exit"). ``MK_COMPILED=0`` keeps every call
on the numpy path.
"""

from __future__ import annotations

import atexit
import hashlib
import importlib
import importlib.util
import os
import pickle
import re
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

from manipulator_kinematics import stopping

#: Run by the child that fills a cold cache: the (module, warm, sample) pickled on its stdin. It
#: ends itself when its parent is gone (SIGKILLed: nothing else would stop it) and leaves
#: SIGINT to the parent (a terminal's Ctrl-C reaches both; the parent kills it).
_CHILD = """
import importlib, os, pickle, signal, sys, threading, time
signal.signal(signal.SIGINT, signal.SIG_IGN)
parent = os.getppid()
def orphaned():
    while os.getppid() == parent:
        time.sleep(0.2)
    os._exit(1)
threading.Thread(target=orphaned, daemon=True).start()
module, warm, sample = pickle.load(sys.stdin.buffer)
warm(importlib.import_module(module), *sample)
"""
#: How often the loader looks whether its process is ending while the child compiles, s.
POLL = 0.05


def enabled() -> bool:
    """False when ``MK_COMPILED=0`` asks for the numpy path everywhere (e.g. to compare)."""
    return os.environ.get("MK_COMPILED", "1") != "0"


class Kernel:
    """The compiled module ``module`` once ``warm(module, *sample)`` has run each of its functions
    once (``sample``: the arguments of the first :meth:`get`, e.g. a machine's packed constants)."""

    def __init__(self, module: str, warm: Callable[..., None]) -> None:
        self.module = module
        self._warm = warm
        # The loaded module, None until then (what get returns): a call on the hottest path reads
        # it directly, ``KERNEL.ready or KERNEL.get()``, a method call costing 0.1 us (the
        # excavator's full state: 7 % of its 1.4 us). None pretends it is not loaded (tests).
        self.ready: ModuleType | None = None
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None  # why the kernel is not used, if it failed to load

    def _load(self, sample: tuple[Any, ...], in_child: bool) -> None:
        try:
            if _ending():
                return
            if in_child and cache_is_cold(self.module) and not self._compile_in_child(sample):
                return  # abandoned: the process is ending
            if _ending():
                return
            module = importlib.import_module(self.module)
            self._warm(module, *sample)
        except Exception as error:  # the numpy path answers; the reason is kept
            self.error = error
            return
        self.ready = module

    def _compile_in_child(self, sample: tuple[Any, ...]) -> bool:
        """Fill numba's cache for the module in a child process; False if the process began to
        end first (the child killed). A child that fails leaves the compile to this process."""
        try:
            job = pickle.dumps((self.module, self._warm, sample))
        except Exception:  # e.g. a lambda as warm function: compile here
            return True
        child = subprocess.Popen(
            [sys.executable, "-c", _CHILD],
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        _COMPILING.append(child)
        try:
            child.stdin.write(job)
            child.stdin.close()
        except OSError:  # it ended before reading: its exit status tells
            pass
        while True:
            try:
                child.wait(POLL)
                return True
            except subprocess.TimeoutExpired:
                if _ending():
                    child.kill()
                    child.wait()
                    return False

    def get(self, *sample: Any, wait: bool = False) -> ModuleType | None:
        """The ready module, else None (starting the load on the first call). ``wait``: load it
        now and return it (tests, benchmarks); raises the load's error if it failed."""
        if self.ready is None and enabled():
            with self._lock:
                if self._thread is None:
                    # A daemon (module docstring): a compile runs in a child, abandoned at exit;
                    # a load from the cache is awaited at exit only where rclpy is imported.
                    # ``wait``: compile here (set-up, tests), no child to pickle the sample to.
                    self._thread = threading.Thread(
                        target=self._load, args=(sample, not wait), daemon=True, name=f"kernel {self.module}"
                    )
                    _LOADERS.append(self._thread)
                    self._thread.start()
            if wait:
                self._thread.join()
                if self.error is not None:
                    raise RuntimeError(f"kernel {self.module} did not load") from self.error
        return self.ready


# The loader threads and compiling children of this process.
_LOADERS: list[threading.Thread] = []
_COMPILING: list[subprocess.Popen] = []


def loading() -> bool:
    """Whether a kernel load or compile is still running in this process."""
    return any(thread.is_alive() for thread in _LOADERS)


def abandon() -> None:
    """Kill the children compiling a kernel (their loaders then end without it)."""
    for child in _COMPILING:
        if child.poll() is None:
            child.kill()
            child.wait()


@atexit.register
def _at_exit() -> None:
    """Before finalization: no compile left running; where rclpy is imported, the loads from the
    cache finished (module docstring)."""
    abandon()
    if "rclpy" in sys.modules:
        for thread in _LOADERS:
            thread.join()


def exit_now_if_loading(code: int) -> None:
    """End the process with ``code`` at once, without finalizing, if a kernel is still loading:
    for a program whose rclpy is shut down cleanly and that has nothing else to finalize (a
    node after :func:`manipulator_kinematics.node_util.run`)."""
    if loading():
        abandon()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def _ending() -> bool:
    """Whether this process is ending: its main thread has finished (the interpreter is joining
    the other threads) or SIGINT/SIGTERM arrived."""
    return stopping.requested() or not threading.main_thread().is_alive()


def cache_is_cold(module: str) -> bool:
    """Whether numba's cache has no index for ``module``, or only indexes older than its source,
    in each place numba looks (module docstring), counting the functions its source defines. A
    guess made without importing numba: a wrong "warm" costs one compile in this process, a wrong
    "cold" one child that loads and ends."""
    spec = importlib.util.find_spec(module)
    if spec is None or not spec.origin or not spec.origin.endswith(".py"):
        return False  # nothing numba compiles from a file (or no module: the import says why)
    source = Path(spec.origin)
    # numba's subdirectory of a cache root: the source's directory name and a hash of its path
    folder = str(source.parent.absolute())
    sub = f"{source.parent.name}_{hashlib.sha1(folder.encode()).hexdigest()}"
    xdg = os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")
    places = [source.parent / "__pycache__", Path(xdg, "numba", sub)]
    if os.environ.get("NUMBA_CACHE_DIR"):
        places = [Path(os.environ["NUMBA_CACHE_DIR"], sub)]  # numba then looks nowhere else first
    stamp = source.stat().st_mtime
    # The functions the source defines now: the index of one since removed or renamed stays
    # behind in the cache for ever, and would keep the module cold.
    defined = set(re.findall(r"^\s*def (\w+)\(", source.read_text(encoding="utf-8"), flags=re.MULTILINE))
    for place in places:
        # <stem>.<function>-<line>.py311.nbi: an edit above a function leaves its index under the
        # old line behind, so each function counts by its newest index.
        newest: dict[str, float] = {}
        for index in place.glob(f"{source.stem}.*.nbi"):
            function = index.name[len(source.stem) + 1 :].rsplit("-", 1)[0]
            if function in defined:
                newest[function] = max(newest.get(function, 0.0), index.stat().st_mtime)
        if newest and all(mtime >= stamp for mtime in newest.values()):
            return False
    return True
