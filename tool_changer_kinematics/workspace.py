"""Monte-Carlo workspace of the tool changer (paper section 3, Figs. 5 and 6); numpy only.

Random joint vectors, uniform within the joint limits and seeded, are mapped through the FK
(eq. 2) in blocks of rows; the extents are the largest horizontal radius sqrt(x^2 + y^2), the largest
height z and the largest depth -z of the tool point in the base frame. Monte Carlo approaches the
extents from inside (depth slowest: 10^6 samples give about 956 mm against an optimum of about
977 mm on the reconstructed arm), so the sample count goes with every number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from manipulator_kinematics.row_blocks import in_blocks
from tool_changer_kinematics.kinematics import ToolChanger


@dataclass(frozen=True)
class Workspace:
    """Tool points ``points`` (N, 3) m of joint samples ``q`` (N, 6) and their extents (m)."""

    q: np.ndarray
    points: np.ndarray

    @property
    def samples(self) -> int:
        return len(self.points)

    @property
    def max_radius(self) -> float:
        return float(np.hypot(self.points[:, 0], self.points[:, 1]).max())

    @property
    def max_height(self) -> float:
        return float(self.points[:, 2].max())

    @property
    def max_depth(self) -> float:
        return float(-self.points[:, 2].min())

    def summary(self) -> str:
        return (
            f"{self.samples} samples: max radius {self.max_radius * 1e3:.0f} mm, max height "
            f"{self.max_height * 1e3:.0f} mm, max depth {self.max_depth * 1e3:.0f} mm"
        )


def sample(arm: ToolChanger, n: int = 1_000_000, seed: int = 0, theta1: float | None = None) -> Workspace:
    """``n`` uniform joint samples within the limits; ``theta1`` fixes J1 (rad; Fig. 6: pi / 2)."""
    q = np.random.default_rng(seed).uniform(arm.limits.lower, arm.limits.upper, (n, 6))
    if theta1 is not None:
        q[:, 0] = theta1
    points = in_blocks(lambda block: arm.fkine(block)[:, :3, 3], q)  # bounded memory for 10^6 samples
    return Workspace(q=q, points=points)


def section(arm: ToolChanger, n: int = 200_000, seed: int = 1) -> Workspace:
    """The paper's Fig. 6: J1 at 90 deg, the arm working in the y0-z0 plane of the shield axis."""
    return sample(arm, n, seed, theta1=math.pi / 2)
