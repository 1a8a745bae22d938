"""The demo's planned move (issue #18 item 5), ROS-free: a trajectory of D = [theta1, d2, d3, d4]
from ``plan_path`` executed as rate commands, the arrival check, and its plot.

The simulator takes rate commands only (``cylinder_rate_commands``), so the move is streamed as
rates: on each measured state, the planned velocity (fed forward :data:`LEAD` ahead of the
state's stamp, as the digging driver does) plus :data:`GAIN` x (planned - measured position),
at the trajectory time of the state's stamp (a :class:`~excavator_kinematics.demo.bucket_path.CycleClock`,
held over gaps, so a stalled machine does not fall behind a running reference). After the
trajectory's end the reference holds its last sample for :data:`SETTLE` s; then the measured D
is compared with the start (:data:`TOLERANCE`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from excavator_kinematics.core.kinematics import ACTUATORS

if TYPE_CHECKING:
    from excavator_kinematics.core.kinematics import Excavator

#: 1/s: position feedback on each actuator (the loop's dead time, about 40 ms, allows ~10/s).
GAIN = 5.0
#: s: the planned velocity is fed forward this far ahead of the state's stamp (simulator lag
#: 20 ms + transport, as the digging driver's LEAD).
LEAD = 0.04
#: s of trajectory time after its end before the arrival check (e^-(GAIN SETTLE) of an error left).
SETTLE = 1.0
#: Accepted distance of the arrived D from the start: swing (rad), then the three cylinders (m).
TOLERANCE = np.array([1e-3, 1e-3, 1e-3, 1e-3])
#: Accepted distance of the arrived bucket tip from the start (m).
TIP_TOLERANCE = 1e-3


@dataclass(frozen=True)
class Trajectory:
    """Timed D: ``t`` (N,) s, ``q`` and ``qd`` (N, 4) in :data:`ACTUATORS` order."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray

    @classmethod
    def from_points(
        cls, names: list[str], t: list[float], q: list[list[float]], qd: list[list[float]]
    ) -> Trajectory:
        """From a JointTrajectory's joint names and points, reordered to ACTUATORS (ValueError
        when a joint is missing or there is no point)."""
        missing = [n for n in ACTUATORS if n not in names]
        if missing or not t:
            raise ValueError(f"trajectory without {', '.join(missing) or 'points'}")
        order = [names.index(n) for n in ACTUATORS]
        return cls(
            np.asarray(t, dtype=float),
            np.asarray(q, dtype=float)[:, order],
            np.asarray(qd, dtype=float)[:, order],
        )

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """q and qd at ``t``, linear between samples, held at the ends (qd 0 after the end)."""
        q = np.array([np.interp(t, self.t, column) for column in self.q.T])
        qd = np.array([np.interp(t, self.t, column, right=0.0) for column in self.qd.T])
        return q, qd

    def command(self, t: float, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rate command, planned q) at trajectory time ``t`` for the measured D."""
        q, _ = self.at(t)
        _, qd = self.at(t + LEAD)
        return qd + GAIN * (q - measured), q


@dataclass(frozen=True)
class Arrival:
    """The arrived D against the start: ``error`` (4,) |D - start|, ``tip_error`` (m), ``ok``."""

    error: np.ndarray
    tip_error: float

    @property
    def ok(self) -> bool:
        return bool(np.all(self.error <= TOLERANCE) and self.tip_error <= TIP_TOLERANCE)


def arrival(exc: Excavator, measured: np.ndarray, start: np.ndarray) -> Arrival:
    """How far the measured D (4,) ended from ``start`` (4,), in D and at the bucket tip."""
    tip = np.linalg.norm(exc.pose(measured)[:3] - exc.pose(start)[:3])
    return Arrival(np.abs(np.asarray(measured) - start), float(tip))


def plot(
    png: Path, exc: Excavator, t: np.ndarray, d: np.ndarray, d_dot: np.ndarray, plan: Trajectory
) -> Path:
    """Positions and speeds of the four actuators over the move (measured at times ``t`` (N,),
    ``d``/``d_dot`` (N, 4); planned), against the strokes and the speed limits."""
    import matplotlib.pyplot as plt

    lim = exc.limits
    units = ["rad", "m", "m", "m"]
    fig, axes = plt.subplots(2, 4, figsize=(16, 6.5), sharex=True, constrained_layout=True)
    for i, name in enumerate(ACTUATORS):
        top, bottom = axes[0, i], axes[1, i]
        top.plot(plan.t, plan.q[:, i], "--", color="tab:gray", label="planned")
        top.plot(t, d[:, i], color="tab:blue", label="simulated")
        for bound in (lim.d_min[i], lim.d_max[i]):
            if np.isfinite(bound):  # a continuous swing has none
                top.axhline(bound, color="tab:red", lw=0.8)
        top.set_title(name)
        top.set_ylabel(f"position ({units[i]})")
        bottom.plot(plan.t, plan.qd[:, i], "--", color="tab:gray", label="planned")
        bottom.plot(t, d_dot[:, i], color="tab:blue", label="simulated")
        for bound in (-lim.max_rates[i], lim.max_rates[i]):
            bottom.axhline(bound, color="tab:red", lw=0.8, label="limit" if bound > 0 else None)
        bottom.set_ylabel(f"speed ({units[i]}/s)")
        bottom.set_xlabel("t (s)")
    axes[1, 0].legend(loc="best", fontsize=8)
    fig.suptitle(
        f"{exc.name}: planned move back to the start (plan_path, {plan.duration:.2f} s); "
        "red: strokes and speed limits"
    )
    fig.savefig(png, dpi=90)
    plt.close(fig)
    return png
