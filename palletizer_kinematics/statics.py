"""Static holding torques of axes 2 and 3 under gravity and payload (paper 004, eqs. 12-15). numpy only.

The paper's mass data are not published (only its results survive), so the mass model is a
configured set of lumped bodies (``masses`` in config/irb460.yaml; the shipped values are this
project's plausible guesses for a 110 kg palletizer). Bodies, in the arm's vertical plane, with
phi = A2 the lower arm's tilt from vertical (forward > 0) and psi = theta2 + theta3 the upper
arm's angle below horizontal (= A3 of the double robot, A2 + A3 of the single one):

* lower arm (mass m2, centre lC2 from axis 2 along it), auxiliary rod beside it (m_r1, l_r1 from
  its base pivot): both turn with phi;
* elbow plate of the auxiliary parallelograms (m_p): translates with the elbow;
* upper arm (m3, lC3 from the elbow toward the wrist) and the second auxiliary rod (m_r2, l_r2):
  turn with psi about points that move with the elbow;
* wrist (m_w) and payload (m_L): translate with the wrist pin D (the parallelograms keep them
  level, so their horizontal offsets from D load the parallelogram rods, not axes 2 and 3);
* double only, the main parallelogram: crank (m_k, centre lCk behind axis 2, crank radius r_k)
  turning with psi about axis 2, and the main rod (m_m, centre l_m from the crank pin) parallel
  to the lower arm.

With V the potential energy, the motor torque that holds a pose is tau = dV/dA (positive in the
axis' positive sense; the paper prints magnitudes). Writing

    P = g [m2 lC2 + m_r1 l_r1 + (m3 + m_r2 + m_p + m_w + m_L) a2 (+ m_m l_m)]     lower-arm moment
    Q = g [m3 lC3 + m_r2 l_r2 + (m_w + m_L) a3 (- m_k lCk - m_m r_k)]             upper-arm moment

(the terms in brackets for the double robot only), dV/dphi = -P sin(phi), dV/dpsi = -Q cos(psi):

* single parallelogram (axis 3 between lower and upper arm, psi = A2 + A3):
  eq. (12) T3 = -Q cos(A2 + A3), eq. (13) T2 = -P sin(A2) + T3 (axis 2 carries the upper arm's
  moment too, because the axis-3 drive sits on the lower arm);
* double parallelogram (axis 3 on the base, psi = A3):
  eq. (14) T3 = -Q cos(A3), eq. (15) T2 = -P sin(A2) (the upper arm's moment goes to the base
  through the main parallelogram; axis 2 holds only its weight at the elbow pin).

Hence the paper's conclusion: in the same pose the double robot's T2 is smaller by about T3,
roughly half, while T3 differs only by the crank's and main rod's counter-moment.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.schema import Number, Schema

_KG = Number(min=0.0, max=10_000.0, unit="kg")
_M = Number(min=-10.0, max=10.0, unit="m")

#: ``palletizer.masses``: the lumped bodies of the module docstring.
MASS_SCHEMA: Schema = {
    "gravity": Number(min=0.0, max=100.0, unit="m/s^2", doc="gravitational acceleration"),
    "payload": Number(min=0.0, max=10_000.0, unit="kg", doc="payload at the TCP, gripper included"),
    "lower_arm": {"mass": _KG, "com": _M},
    "lower_rod": {"mass": _KG, "com": _M},
    "elbow_plate": {"mass": _KG},
    "upper_arm": {"mass": _KG, "com": _M},
    "upper_rod": {"mass": _KG, "com": _M},
    "wrist": {"mass": _KG},
    "crank": {"mass": _KG, "com": _M, "radius": Number(min=0.0, max=10.0, unit="m")},
    "main_rod": {"mass": _KG, "com": _M},
}


@dataclass(frozen=True)
class MassModel:
    """Masses (kg) and centre distances (m) of the module docstring's bodies."""

    gravity: float
    payload: float
    m2: float
    lc2: float
    m_r1: float
    l_r1: float
    m_p: float
    m3: float
    lc3: float
    m_r2: float
    l_r2: float
    m_w: float
    m_k: float
    lck: float
    r_k: float
    m_m: float
    l_m: float

    @classmethod
    def from_parameters(cls, p: Mapping[str, Any]) -> MassModel:
        """From the validated ``masses`` section."""
        return cls(
            p["gravity"],
            p["payload"],
            p["lower_arm"]["mass"],
            p["lower_arm"]["com"],
            p["lower_rod"]["mass"],
            p["lower_rod"]["com"],
            p["elbow_plate"]["mass"],
            p["upper_arm"]["mass"],
            p["upper_arm"]["com"],
            p["upper_rod"]["mass"],
            p["upper_rod"]["com"],
            p["wrist"]["mass"],
            p["crank"]["mass"],
            p["crank"]["com"],
            p["crank"]["radius"],
            p["main_rod"]["mass"],
            p["main_rod"]["com"],
        )

    def with_payload(self, payload: float) -> MassModel:
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        return MassModel(**{**values, "payload": float(payload)})


class _Arms(Protocol):
    a2: float
    a3: float


class Arm(Protocol):
    """What the statics read of a robot (a ``kinematics.Palletizer``): the arm lengths, the mass
    model and the variant. A protocol, so that kinematics imports this module and not the reverse."""

    geometry: _Arms
    masses: MassModel
    variant: str


def moments(model: Arm, variant: str) -> tuple[float, float]:
    """(P, Q) in N m of the module docstring for ``variant`` (the crank and main rod only in ``double``)."""
    m, g = model.masses, model.geometry
    double = variant == "double"
    carried = m.m3 + m.m_r2 + m.m_p + m.m_w + m.payload
    p = m.m2 * m.lc2 + m.m_r1 * m.l_r1 + carried * g.a2 + (m.m_m * m.l_m if double else 0.0)
    q = (
        m.m3 * m.lc3
        + m.m_r2 * m.l_r2
        + (m.m_w + m.payload) * g.a3
        - (m.m_k * m.lck + m.m_m * m.r_k if double else 0.0)
    )
    return m.gravity * p, m.gravity * q


def holding_torques(model: Arm, axis: ArrayLike, variant: str | None = None) -> np.ndarray:
    """[T2, T3] (..., 2) N m holding axis angles (..., 4) of ``variant`` (default: the model's): eqs. 12-15.

    Axis angles are [A1, A2, A3, A6] in that variant's convention; A1 and A6 turn about vertical
    axes and do not change the torques.
    """
    variant = model.variant if variant is None else variant
    if variant not in ("single", "double"):
        raise ValueError(f"unknown variant {variant!r}; known: single, double")
    axis = np.asarray(axis, dtype=float)
    a2, a3 = axis[..., 1], axis[..., 2]
    p, q = moments(model, variant)
    if variant == "double":
        t3 = -q * np.cos(a3)  # eq. (14)
        t2 = -p * np.sin(a2)  # eq. (15)
    else:
        t3 = -q * np.cos(a2 + a3)  # eq. (12)
        t2 = -p * np.sin(a2) + t3  # eq. (13)
    return np.stack([t2, t3], axis=-1)
