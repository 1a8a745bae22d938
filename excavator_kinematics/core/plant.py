"""Simulated excavator actuators: swing and the three cylinders follow rate commands within their
speed limits and stroke ends (a continuous swing turns on, its angle wrapped to (-pi, pi]). Numpy
only; the simulator node wires it to ROS.

Each actuator saturates at its own maximum speed (a valve opens no further), follows the commanded
rate with a first-order lag of ``time_constant`` seconds (0 = ideal), and stops at its stroke end.
The lag is integrated exactly for a command held over the step, so the result does not depend on
the step size.
"""

from __future__ import annotations

import numpy as np

from excavator_kinematics.core.machine_file import Limits, wrap_swing
from manipulator_kinematics.param_files import ConfigError


class Plant:
    """State D = [theta1, d2, d3, d4] and its rate D_dot, advanced by :meth:`step`."""

    def __init__(self, limits: Limits, d0: np.ndarray, time_constant: float = 0.0) -> None:
        d0 = np.asarray(d0, dtype=float)
        if d0.shape != (4,) or not np.all(np.isfinite(d0)):
            raise ConfigError(f"start state must be 4 finite numbers [swing, boom, arm, bucket], got {d0!r}")
        if np.any(d0 < limits.d_min) or np.any(d0 > limits.d_max):
            raise ConfigError(
                f"start state {d0.tolist()} outside the limits "
                f"[{limits.d_min.tolist()}, {limits.d_max.tolist()}]"
            )
        if not time_constant >= 0.0:
            raise ConfigError(f"time_constant must be >= 0, got {time_constant}")
        self.limits = limits
        self.time_constant = float(time_constant)
        self.d = d0.copy()
        self.d_dot = np.zeros(4)

    def step(self, command: np.ndarray, dt: float) -> None:
        """Advance by ``dt`` seconds holding the rate ``command`` (4,).

        Speeds and stroke ends hold exactly (no ulp beyond): the lag moves the rate towards a
        target clipped to the speed limits without overshoot, and D is clipped to its ends.
        ValueError for a command or step that is not finite (the state would be lost to NaN).
        """
        command = np.asarray(command, dtype=float)
        if command.shape != (4,) or not np.all(np.isfinite(command)) or not np.isfinite(dt):
            raise ValueError(f"plant step needs 4 finite rates and a finite dt, got {command!r}, {dt!r}")
        if dt <= 0.0:
            return
        target = np.clip(command, -self.limits.max_rates, self.limits.max_rates)
        if self.time_constant > 0.0:
            decay = np.exp(-dt / self.time_constant)
            # d(t) for d_dot' = (target - d_dot) / tau, integrated over the step.
            travel = target * dt + (self.d_dot - target) * self.time_constant * (1.0 - decay)
            d_dot = target + (self.d_dot - target) * decay
        else:
            travel = target * dt
            d_dot = target
        d = self.d + travel
        stopped = (d <= self.limits.d_min) & (d_dot <= 0.0) | (d >= self.limits.d_max) & (d_dot >= 0.0)
        self.d = np.clip(d, self.limits.d_min, self.limits.d_max)
        if self.limits.continuous_swing:
            self.d[0] = wrap_swing(self.d[0])
        # In reals the lag cannot overshoot its target; the clip makes that so in floats too.
        self.d_dot = np.where(stopped, 0.0, np.clip(d_dot, -self.limits.max_rates, self.limits.max_rates))
