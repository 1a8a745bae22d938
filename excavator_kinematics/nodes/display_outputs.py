"""What the excavator forward node adds for displays (numpy, no rclpy).

**Grade indication** (the number a machine-control display shows the operator): the signed height
of the bucket teeth (the tip Q[:3] of eq. 3) above a design surface, a plane through ``point``
with the unit normal ``n`` (n_z > 0, so "above" is up): ``h = n . (tip - point)``, the
perpendicular distance, positive above the plane (material to cut), negative below (to fill).
For a level plane it is the height difference in z. The plane is given in the base frame either
by its normal (any length) or by slope and cross-slope in percent (rise per run x 100 along the
base frame's x and y): ``z = z0 + slope/100 (x - x0) + cross_slope/100 (y - y0)``, normal
``(-slope/100, -cross_slope/100, 1)`` normalised. Neither given: level.

The surface frame, in which the node reports the tip: origin ``point``, z = n, x = the base
frame's x projected onto the plane (never zero: n_z > 0), y = z x x. The tip's z in it is h; its
x and y say where along the surface the teeth are.

**Every URDF joint with its rate** (:data:`excavator_kinematics.core.urdf_joints.URDF_JOINTS`): the
positions are :func:`~excavator_kinematics.core.urdf_joints.joint_positions`; the rates of the swing
and the cylinders are the state's own, and every other joint's angle depends on one cylinder
length only (its loop closes on that cylinder, eqs. 1-2 of paper 000), so its rate is
``d angle / d length x length rate`` with the derivative a central difference over +-``step`` of
that length (one-sided at a stroke end).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.urdf_joints import URDF_JOINTS, joint_positions
from manipulator_kinematics.schema import require

# Which D column drives each URDF joint: 0 the swing, 1-3 the boom, arm and bucket cylinder.
_DRIVER = np.array([0, 1, 2, 3, 1, 1, 2, 2, 3, 3, 3, 3])
# Columns of URDF_JOINTS whose value is a D entry itself (the swing and the cylinder lengths).
_OWN = np.array([name == "swing_joint" or name.endswith("_cylinder") for name in URDF_JOINTS])
#: Length step (m) of the central difference for the passive joints' rates.
STEP = 1e-6


@dataclass(frozen=True)
class DesignPlane:
    """A design surface: a plane through ``point`` with unit normal ``normal`` (base frame, n_z > 0)."""

    point: np.ndarray
    normal: np.ndarray
    #: Rows: the surface frame's x, y, z axes in the base frame (module docstring); computed once,
    #: as the node evaluates :meth:`local` on every input.
    rotation: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        n = self.normal
        x = np.array([1.0, 0.0, 0.0]) - n[0] * n
        x /= np.linalg.norm(x)
        object.__setattr__(self, "rotation", np.stack([x, np.cross(n, x), n]))

    @classmethod
    def from_settings(cls, section: Mapping[str, Any], prefix: str = "grade") -> DesignPlane:
        """From the node's ``grade`` settings: ``point`` and either ``normal`` or ``slope`` and
        ``cross_slope`` (%), or neither (level). ConfigError naming the key when inconsistent."""
        normal, slope, cross = section.get("normal"), section.get("slope"), section.get("cross_slope")
        require(
            normal is None or (slope is None and cross is None),
            f"{prefix}.normal",
            f"give either {prefix}.normal or {prefix}.slope/{prefix}.cross_slope, not both",
        )
        if normal is None:
            normal = [-(slope or 0.0) / 100.0, -(cross or 0.0) / 100.0, 1.0]
        n = np.asarray(normal, dtype=float)
        length = float(np.linalg.norm(n))
        require(
            length > 0.0 and n[2] > 1e-6 * length,
            f"{prefix}.normal",
            f"must point up (n_z > 0: the height is measured upward), got {list(normal)}",
        )
        return cls(np.asarray(section["point"], dtype=float), n / length)

    def height(self, tip: ArrayLike) -> np.ndarray:
        """Signed height (...,) of points ``tip`` (..., 3) above the plane (m)."""
        return (np.asarray(tip, dtype=float) - self.point) @ self.normal

    def local(self, tip: ArrayLike) -> np.ndarray:
        """Points ``tip`` (..., 3) in the surface frame; z is :meth:`height`."""
        return (np.asarray(tip, dtype=float) - self.point) @ self.rotation.T


def urdf_joint_states(
    model: Excavator, D: ArrayLike, D_dot: ArrayLike, step: float = STEP
) -> tuple[np.ndarray, np.ndarray]:
    """Positions and rates (12,) or (N, 12) of every URDF joint for states D (4,) or (N, 4) moving at
    D_dot (broadcast to D).

    One batched :func:`joint_positions` call over D and D with every cylinder length moved by
    +-``step`` (clipped to the stroke); raises StrokeError as the model does.
    """
    D = model.validate(D)
    D_dot = np.broadcast_to(np.asarray(D_dot, dtype=float), D.shape)
    lower, upper = model.limits.d_min, model.limits.d_max
    shift = np.array([0.0, step, step, step])
    plus, minus = np.minimum(D + shift, upper), np.maximum(D - shift, lower)
    plus[..., 0] = minus[..., 0] = D[..., 0]
    # The model takes (N, 4): the three states of every row in one batch.
    values = joint_positions(model, np.stack([D, plus, minus]).reshape(-1, 4)).reshape(3, *D.shape[:-1], -1)
    change = values[1] - values[2]
    change[..., ~_OWN] = (change[..., ~_OWN] + np.pi) % (2.0 * np.pi) - np.pi
    span = (plus - minus)[..., _DRIVER]
    rates = np.where(_OWN, D_dot[..., _DRIVER], change / np.where(_OWN, 1.0, span) * D_dot[..., _DRIVER])
    return values[0], rates
