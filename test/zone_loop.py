"""A velocity IK's zone check and its simulated actuators in one plain loop at the nodes' rates,
with the transport between the processes: the fast numeric stand-in for the zone tests across
processes (test_zones_ros.py, test_zones_family_ros.py).

The simulator steps every 1 / ``rate`` s (a step late by ``stall_time`` with the chance
``stall``: a loaded machine), integrating each step with the last command it has received, and
sends its state; the velocity IK receives it ``way_in`` s later (in order), computes a command
from it at once and checks it against the zones with the period and delay the node gives
(:class:`manipulator_kinematics.zone_guard.CommandTimes`); the command reaches the simulator
``way_out`` s after that. Delays are uniform in their ranges."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from manipulator_kinematics.zone_guard import CommandTimes, ZoneGuard

#: Crossing allowed in this loop, m: the check predicts a point's path to second order over its
#: horizon; the third-order term (jerk x sigma^3 / 6, about 1e-7 m over 50 ms) and round-off are
#: below it.
CURVE_TOLERANCE = 1e-6
#: A velocity IK's own rules for a state (and the time, s): the command's actuator rates and the
#: monitored points' positions, velocities and accelerations (P, 3) for it.
Command = Callable[[np.ndarray, float], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Timing:
    """How the processes meet (module docstring); the default: an idle machine."""

    rate: float = 100.0
    way_in: tuple[float, float] = (0.0005, 0.003)
    way_out: tuple[float, float] = (0.0005, 0.003)
    stall: float = 0.0
    stall_time: tuple[float, float] = (0.0, 0.0)


#: An idle machine: sub-ms to 3 ms each way.
IDLE = Timing()
#: A loaded machine: a few ms each way, jittering, and one simulator step in 20 late by 10-40 ms.
LOADED = Timing(way_in=(0.001, 0.012), way_out=(0.001, 0.012), stall=0.05, stall_time=(0.01, 0.04))


def drive(
    plant, command: Command, guard: ZoneGuard, seconds: float, timing: Timing, seed: int, curved: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """The simulator's states (N, m), one per step, and the zone scale of every command (M,),
    for ``seconds`` of simulated time from the plant's state. ``curved`` False: the guard is
    given no accelerations (the points' paths taken as straight)."""
    rng = np.random.default_rng(seed)
    times = CommandTimes()
    pending: list[tuple[float, np.ndarray]] = []  # (arrival at the simulator, rates)
    in_force = np.zeros_like(plant.d)
    now, received = 0.0, 0.0
    states, scales = [], []
    while True:
        step = 1.0 / timing.rate
        if rng.uniform() < timing.stall:
            step += rng.uniform(*timing.stall_time)
        now += step
        while pending and pending[0][0] <= now:  # the simulator's: the last received, over the step
            in_force = pending.pop(0)[1]
        plant.step(in_force, step)
        states.append(plant.d.copy())
        if now > seconds - 1e-9:  # the last state: no command from it (the targets end here)
            break
        received = max(now + rng.uniform(*timing.way_in), received)
        rates, p, v, a = command(plant.d.copy(), now)
        period, delay = times(received, now)
        verdict = guard.check(p, v, rates, period=period, accelerations=a if curved else None, delay=delay)
        scales.append(verdict.scale)
        pending.append((received + rng.uniform(*timing.way_out), verdict.scale * rates))
    return np.array(states), np.array(scales)
