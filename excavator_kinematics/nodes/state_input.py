"""How the excavator nodes combine inputs of different rates and derive accelerations (no ROS).

* Swing and cylinders arrive on separate topics (``joint_states`` and ``cylinder_lengths``) at
  their own rates. A node computes on each cylinder message with the latest swing state,
  extrapolated to the cylinder message's stamp with the swing rate (first-order hold), provided
  the two stamps are at most ``max_age`` seconds apart; otherwise the input is rejected.
* sensor_msgs/JointState has no acceleration field, so accelerations are finite differences of
  successive rates over the header stamps, optionally low-pass filtered with a first-order filter
  of time constant ``time_constant`` (0 = raw differences). The first message, a stamp that does
  not increase, or a gap longer than ``max_gap`` restarts the differencing: no acceleration for
  that message.

Stamps are integer nanoseconds, so differences are exact.

Plausibility (:class:`Plausible`): a rate beyond ``PLAUSIBILITY_FACTOR`` (1000, the package's one
factor, :mod:`manipulator_kinematics.joint_state`) times the actuator's speed
limit, or an acceleration beyond that rate reached from standstill in ``FASTEST_RAMP`` seconds, is
not a measurement of this machine but a corrupt input. Refusing it where it enters also keeps
every product downstream (twists, finite differences, the squared rates of eq. 11) many orders of
magnitude from overflow: two finite rates of 1.7e308 of opposite sign would otherwise difference
to -inf.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from manipulator_kinematics.joint_state import PLAUSIBILITY_FACTOR, InputError
from manipulator_kinematics.param_files import ConfigError

#: Quickest plausible ramp (s) from standstill to PLAUSIBILITY_FACTOR x the speed limit.
FASTEST_RAMP = 0.01


class Plausible:
    """Bounds of plausible rates and accelerations per actuator name, from its speed limit."""

    def __init__(self, names: Sequence[str], max_rates: Sequence[float]) -> None:
        self.rate = {name: PLAUSIBILITY_FACTOR * float(m) for name, m in zip(names, max_rates, strict=True)}
        self.acceleration = {name: bound / FASTEST_RAMP for name, bound in self.rate.items()}

    def rates(self, names: Sequence[str], values: Sequence[float]) -> None:
        """InputError naming the first rate beyond its bound."""
        _check(names, values, self.rate, "rate", "speed limit")

    def accelerations(self, names: Sequence[str], values: Sequence[float]) -> None:
        """InputError naming the first acceleration beyond its bound."""
        _check(names, values, self.acceleration, "acceleration", f"speed limit / {FASTEST_RAMP:g} s")


def _check(
    names: Sequence[str], values: Sequence[float], bounds: dict[str, float], what: str, limit: str
) -> None:
    # Plain Python: this runs on every message of a 1 kHz stream.
    for name, value in zip(names, values, strict=True):
        bound = bounds[name]
        if not abs(value) <= bound:
            raise InputError(
                f"{name} {what} {value:.6g} is beyond {PLAUSIBILITY_FACTOR:g} x its {limit} "
                f"(|{what}| <= {bound:.6g}): implausible"
            )


class StaleInput(InputError):
    """An input that is late or not there yet: transient on a loaded machine and at start-up (the
    topics start at different moments), not a fault that needs a person. Nodes log it as a
    warning (throttled), before their first output as one info line."""


class SwingHold:
    """The latest swing state (angle, rate, acceleration), read at a cylinder message's stamp."""

    def __init__(self, max_age: float) -> None:
        self.max_age_ns = int(max_age * 1e9)
        self._stamp_ns: int | None = None
        self._angle = self._rate = 0.0
        self._acceleration: float | None = None

    def update(self, stamp_ns: int, angle: float, rate: float, acceleration: float | None) -> None:
        self._stamp_ns, self._angle, self._rate, self._acceleration = stamp_ns, angle, rate, acceleration

    def at(self, stamp_ns: int) -> tuple[float, float, float | None]:
        """(angle, rate, acceleration or None) at ``stamp_ns``; StaleInput when missing or too old."""
        if self._stamp_ns is None:
            raise StaleInput("no swing state received yet (joint_states with swing_joint)")
        gap_ns = stamp_ns - self._stamp_ns
        if abs(gap_ns) > self.max_age_ns:
            raise StaleInput(
                f"swing state is {gap_ns * 1e-9:+.3f} s from the cylinder stamp "
                f"(max age {self.max_age_ns * 1e-9:g} s)"
            )
        return self._angle + self._rate * gap_ns * 1e-9, self._rate, self._acceleration


class RateDifferentiator:
    """Accelerations from successive rates: (v_k - v_k-1) / (t_k - t_k-1), then a first-order low-pass."""

    def __init__(self, time_constant: float, max_gap: float) -> None:
        if not time_constant >= 0.0 or not max_gap > 0.0:
            raise ConfigError(f"need time_constant >= 0 and max_gap > 0, got {time_constant}, {max_gap}")
        self.time_constant = float(time_constant)
        self.max_gap_ns = int(max_gap * 1e9)
        self._stamp_ns: int | None = None
        self._rates: np.ndarray | None = None
        self._filtered: np.ndarray | None = None

    def restart(self) -> None:
        """Forget the filtered value: the next acceleration is a raw difference again."""
        self._filtered = None

    def update(self, stamp_ns: int, rates: np.ndarray) -> np.ndarray | None:
        """Acceleration at ``stamp_ns``, or None while the differencing (re)starts."""
        rates = np.asarray(rates, dtype=float)
        previous_stamp, previous_rates = self._stamp_ns, self._rates
        self._stamp_ns, self._rates = stamp_ns, rates
        if previous_stamp is None or not 0 < stamp_ns - previous_stamp <= self.max_gap_ns:
            self._filtered = None
            return None
        dt = (stamp_ns - previous_stamp) * 1e-9
        raw = (rates - previous_rates) / dt
        if self._filtered is None or self.time_constant == 0.0:
            self._filtered = raw
        else:
            self._filtered = self._filtered + (raw - self._filtered) * (
                1.0 - math.exp(-dt / self.time_constant)
            )
        return self._filtered
