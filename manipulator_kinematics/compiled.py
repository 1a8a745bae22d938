"""One compiled kernel behind a numpy function: loaded in the background, the numpy path meanwhile.

Every machine's math is plain vectorised numpy on (..., n) arrays, one state being a batch of
one; that path is the reference. Where a user loops over single calls (a node at 1 kHz, an IK
service), numpy's fixed cost per call (about a microsecond per ufunc, hundreds per closed form)
dominates, so the single call runs the same steps as scalar loops compiled by numba, kept in
numba's on-disk cache (``cache=True``: ``__pycache__`` next to the kernel module, or numba's
user-wide cache directory where that is not writable). A test per kernel compares it with the
numpy path (to 1e-12, statuses and selections equal).

:class:`Kernel` imports the kernel module and runs each function once (numba loads it from its
cache, about half a second with numba's import; or compiles it, several seconds the first time)
in a thread (not a daemon: a process ends after the load) started by the first call that can use
it: the first call where the kernel's loop also serves batches faster than numpy (the serial
chain, the tool changer's and the palletizer's IK), else the first single call (the excavator,
SCARA and pump boom IK: a process that only runs their batches never imports numba). Until it
is ready every call takes the numpy path, so a node's first output never waits for numba.
``MK_COMPILED=0`` in the environment keeps every call on the numpy path.
"""

from __future__ import annotations

import importlib
import os
import threading
from collections.abc import Callable
from types import ModuleType
from typing import Any


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

    def _load(self, sample: tuple[Any, ...]) -> None:
        try:
            module = importlib.import_module(self.module)
            self._warm(module, *sample)
        except Exception as error:  # the numpy path answers; the reason is kept
            self.error = error
            return
        self.ready = module

    def get(self, *sample: Any, wait: bool = False) -> ModuleType | None:
        """The ready module, else None (starting the load on the first call). ``wait``: load it
        now and return it (tests, benchmarks); raises the load's error if it failed."""
        if self.ready is None and enabled():
            with self._lock:
                if self._thread is None:
                    # Not a daemon: a process ends only after the load (0.5-1 s from the cache,
                    # the first compile 5-15 s). A daemon thread still running Python when the
                    # interpreter finalizes is ended inside whatever it calls: in rclpy's handle
                    # destructors (the thread's garbage collection) that aborted a signalled node.
                    self._thread = threading.Thread(target=self._load, args=(sample,), daemon=False,
                                                    name=f"kernel {self.module}")
                    self._thread.start()
            if wait:
                self._thread.join()
                if self.error is not None:
                    raise RuntimeError(f"kernel {self.module} did not load") from self.error
        return self.ready
