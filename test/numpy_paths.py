"""Compiled kernels set aside inside a test, so that the numpy reference path answers: the
kernel's loaded module hidden (``Kernel.ready``) and ``MK_COMPILED=0``, so none loads meanwhile."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import pytest

from manipulator_kinematics.compiled import Kernel


@contextlib.contextmanager
def numpy_only(*kernels: Kernel) -> Iterator[None]:
    """Inside, every call served by one of ``kernels`` takes its numpy path."""
    with pytest.MonkeyPatch.context() as patch:
        for kernel in kernels:
            patch.setattr(kernel, "ready", None)
        patch.setenv("MK_COMPILED", "0")
        yield
