#!/usr/bin/env python3
"""Compile (or load) every compiled kernel of the package for its shipped machines, waiting for
each: run at set-up (scripts/bootstrap.sh; after ``colcon build`` with the install sourced), so
that no user's first run compiles (manipulator_kinematics.compiled). Prints one line."""

from __future__ import annotations

import time

from excavator_kinematics.core import inverse
from excavator_kinematics.core import kinematics as excavator
from manipulator_kinematics import serial_chain, zones
from manipulator_kinematics.hydraulic import model as hydraulic
from palletizer_kinematics import kinematics as palletizer
from pump_boom_kinematics import kinematics as pump_boom
from scara_kinematics import kinematics as scara
from tool_changer_kinematics import kinematics as tool_changer


def main() -> None:
    started = time.monotonic()
    model = excavator.Excavator.default()
    loaded = [
        serial_chain.compiled_kernel(wait=True),
        hydraulic.compiled_kernel(wait=True),
        excavator.compiled_kernel(model, wait=True),
        inverse.compiled_kernel(model, wait=True),
        scara.compiled_kernel(scara.Scara.default(), wait=True),
        tool_changer.ToolChanger.default().compiled_kernel(wait=True),
        palletizer.compiled_kernel(palletizer.Palletizer.default(), wait=True),
        pump_boom.compiled_kernel(pump_boom.PumpBoom.default(), wait=True),
        zones.KERNEL.get(wait=True),
    ]
    names = ", ".join(kernel.__name__ for kernel in loaded if kernel is not None)
    print(f"compiled kernels ready in {time.monotonic() - started:.1f} s: {names}")


if __name__ == "__main__":
    main()
