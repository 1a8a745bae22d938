"""The excavator's working ranges (the spec sheet's side-view dimensions) from the geometry alone.

numpy + scipy, no rclpy. The machine stands on level ground; z = 0 of the ranges is the ground,
``base_height`` (m, machine file) below the base frame's origin; r is the horizontal distance from
the swing axis in the boom plane (swing 0). Definitions after SAE J1193 / ISO 7135, measured at
the bucket teeth tip (the bucket tip of eq. 3, paper 000) unless said otherwise:

* ``max_digging_reach``: the largest horizontal distance from the swing axis to the teeth tip,
  at any height;
* ``max_reach_at_ground``: the same, with the teeth tip on the ground (z = 0);
* ``max_digging_depth``: the deepest the teeth tip goes below the ground (positive, m);
* ``max_cutting_height``: the highest the teeth tip goes above the ground;
* ``max_dumping_height``: the highest the teeth tip can be with the bucket in the dump position,
  its line (pin -> teeth) pointing straight down so the teeth are its lowest point (alpha =
  -90 deg); the bucket pin's highest position is reported beside it (``bucket_pin_height``), as
  some sheets quote that instead;
* ``max_vertical_wall_depth``: the deepest the teeth tip goes below the ground with the arm
  vertical (bucket pin straight below the arm pin), the depth of a vertical wall the machine can
  dig. Where the deepest point has the arm vertical anyway (depth is stationary in theta3 and
  theta4 only when arm and bucket both point down, so an interior optimum does), it equals
  ``max_digging_depth``;
* ``min_front_swing_radius``: the smallest radius the front attachment sweeps when the upper
  structure swings: min over the stroke box of the largest r of its pins and teeth (every point
  of :meth:`Excavator.pins` except those on the upper structure), the attachment folded.

Each is an optimum over the stroke box [d2, d3, d4] (scipy.optimize: SLSQP from the best points
of a grid, constraints as equalities; the grid's best points are several starts, so a local
optimum is not mistaken for the global one) and, separately, the best of a dense vectorised grid
(``sampled``; for the two quantities with an equality the grid's edges that cross it are solved
for the crossing by vectorised bisection, so sampled states satisfy it exactly). An optimum is
never worse than a sample (test/test_excavator_working_ranges.py).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import optimize

from excavator_kinematics.core.kinematics import Excavator
from manipulator_kinematics.param_files import ConfigError

#: The table's keys, in spec-sheet order, with a label.
QUANTITIES = {
    "max_digging_reach": "max digging reach",
    "max_reach_at_ground": "max reach at ground level",
    "max_digging_depth": "max digging depth",
    "max_cutting_height": "max cutting height",
    "max_dumping_height": "max dumping height (teeth, bucket dumped)",
    "max_vertical_wall_depth": "max vertical wall digging depth",
    "min_front_swing_radius": "min front swing radius",
}
# Pins on the upper structure: they swing with it at a fixed radius, not part of the attachment.
_BODY_PINS = ("boom_foot", "boom_cylinder_base")
_AT_REST = np.zeros(4)  # D_dot of the joint angles' state (arm_tilt)


@dataclass(frozen=True)
class Range:
    """One quantity: value (m) and the state D = [swing, d2, d3, d4] attaining it."""

    value: float
    state: np.ndarray

    def as_json(self) -> dict[str, object]:
        names = ("swing_joint", "boom_cylinder", "arm_cylinder", "bucket_cylinder")
        return {"value": self.value, "state": dict(zip(names, self.state.tolist(), strict=True))}


class WorkingRanges:
    """The quantities of the module docstring for one machine on level ground."""

    def __init__(self, model: Excavator, base_height: float, grid: int = 41) -> None:
        self.model = model
        self.base_height = float(base_height)
        self.lo, self.hi = model.limits.stroke_min, model.limits.stroke_max
        self.grid = grid

    # ---- quantities of lengths L (..., 3) = [d2, d3, d4], swing 0 --------------------------------
    def _states(self, L: np.ndarray) -> np.ndarray:
        L = np.asarray(L, dtype=float)
        return np.concatenate([np.zeros(L.shape[:-1] + (1,)), L], axis=-1)

    def tip(self, L: np.ndarray) -> np.ndarray:
        """[r, height above ground] (..., 2) of the teeth tip."""
        pose = self.model.pose(self._states(L).reshape(-1, 4)).reshape(np.shape(L)[:-1] + (4,))
        return np.stack([pose[..., 0], pose[..., 2] + self.base_height], axis=-1)

    def bucket_tilt(self, L: np.ndarray) -> np.ndarray:
        """alpha + 90 deg (rad): 0 where the bucket line points straight down."""
        return self.model.pose(self._states(L).reshape(-1, 4))[:, 3].reshape(np.shape(L)[:-1]) + np.pi / 2

    def arm_tilt(self, L: np.ndarray) -> np.ndarray:
        """theta2 + theta3 + 90 deg (rad): 0 where the arm points straight down."""
        # The joints of the full state: its compiled kernel (joint_angles is the numpy core's,
        # 30x slower on the grid's 41^3 states).
        theta = self.model.state(self._states(L).reshape(-1, 4), _AT_REST).theta
        return (theta[:, 1] + theta[:, 2] + np.pi / 2).reshape(np.shape(L)[:-1])

    def front_radius(self, L: np.ndarray) -> np.ndarray:
        """Largest r (...,) of the attachment's pins and teeth."""
        pins = self.model.pins(self._states(L).reshape(-1, 4))
        r = np.max([p[:, 0] for name, p in pins.items() if name not in _BODY_PINS], axis=0)
        return r.reshape(np.shape(L)[:-1])

    def bucket_pin_height(self, L: np.ndarray) -> np.ndarray:
        z = self.model.pins(self._states(L).reshape(-1, 4))["bucket_pin"][:, 2] + self.base_height
        return z.reshape(np.shape(L)[:-1])

    # ---- the problems: (objective to maximise, equality or None) --------------------------------
    def problems(self) -> dict[str, tuple[Callable[[np.ndarray], np.ndarray], Callable | None]]:
        return {
            "max_digging_reach": (lambda L: self.tip(L)[..., 0], None),
            "max_reach_at_ground": (lambda L: self.tip(L)[..., 0], lambda L: self.tip(L)[..., 1]),
            "max_digging_depth": (lambda L: -self.tip(L)[..., 1], None),
            "max_cutting_height": (lambda L: self.tip(L)[..., 1], None),
            "max_dumping_height": (lambda L: self.tip(L)[..., 1], self.bucket_tilt),
            "bucket_pin_height": (self.bucket_pin_height, None),
            "max_vertical_wall_depth": (lambda L: -self.tip(L)[..., 1], self.arm_tilt),
            "min_front_swing_radius": (lambda L: -self.front_radius(L), None),
        }

    def _grid(self) -> np.ndarray:
        axes = [np.linspace(self.lo[i], self.hi[i], self.grid) for i in range(3)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)

    def sampled(self, key: str) -> Range:
        """The best point of the grid (on the equality's crossings for a constrained quantity)."""
        objective, equality = self.problems()[key]
        points = self._grid()
        if equality is not None:
            points = _crossings(equality, points)
        values = objective(points)
        best = int(np.argmax(values))
        return self._range(key, float(values.ravel()[best]), points.reshape(-1, 3)[best])

    def optimum(self, key: str, starts: int = 8) -> Range:
        """SLSQP over the stroke box from the ``starts`` best grid points (module docstring)."""
        objective, equality = self.problems()[key]
        lo, hi = self.lo, self.hi

        def lengths(u: np.ndarray) -> np.ndarray:  # normalised [0, 1] coordinates -> lengths
            return lo + np.clip(u, 0.0, 1.0) * (hi - lo)

        seeds = self._grid()
        if equality is not None:
            seeds = _crossings(equality, seeds)
        values = objective(seeds).ravel()
        order = np.argsort(values)[::-1][:starts]
        candidates = [(float(values[order[0]]), seeds.reshape(-1, 3)[order[0]])]
        constraints = (
            [] if equality is None else [{"type": "eq", "fun": lambda u: float(equality(lengths(u)))}]
        )
        for index in order:
            u0 = (seeds.reshape(-1, 3)[index] - lo) / (hi - lo)
            result = optimize.minimize(
                lambda u: -float(objective(lengths(u))),
                u0,
                method="SLSQP",
                bounds=[(0.0, 1.0)] * len(u0),
                constraints=constraints,
                options={"ftol": 1e-14, "maxiter": 500},
            )
            L = lengths(result.x)
            if equality is None or abs(float(equality(L))) < 1e-10:
                candidates.append((float(objective(L)), L))
        value, L = max(candidates, key=lambda c: c[0])
        return self._range(key, value, L)

    def _range(self, key: str, value: float, L: np.ndarray) -> Range:
        # The objective is maximised: the front swing radius enters negated.
        value = -value if key == "min_front_swing_radius" else value
        return Range(value, self._states(np.asarray(L, dtype=float)))

    def table(self) -> dict[str, dict[str, Range]]:
        """{key: {"optimum": Range, "sampled": Range}} for every key of :data:`QUANTITIES` and
        ``bucket_pin_height``."""
        return {key: {"optimum": self.optimum(key), "sampled": self.sampled(key)} for key in self.problems()}


def _crossings(
    equality: Callable[[np.ndarray], np.ndarray], points: np.ndarray, steps: int = 60
) -> np.ndarray:
    """Points (K, 3) where ``equality`` is 0 on the grid's edges (every axis), by bisection.

    An edge whose two ends have opposite signs holds a root (the function is continuous there);
    60 halvings bring it to the float resolution of the edge.
    """
    values = equality(points)
    found = []
    for axis in range(points.ndim - 1):
        if points.shape[axis] < 2:
            continue
        a = np.moveaxis(points, axis, 0)
        fa = np.moveaxis(values, axis, 0)
        left, right, f_left = a[:-1].reshape(-1, 3), a[1:].reshape(-1, 3), fa[:-1].ravel()
        f_right = fa[1:].ravel()
        cross = np.sign(f_left) != np.sign(f_right)
        left, right, f_left = left[cross], right[cross], f_left[cross]
        for _ in range(steps):
            middle = 0.5 * (left + right)
            f_middle = equality(middle)
            same = np.sign(f_middle) == np.sign(f_left)
            left = np.where(same[:, None], middle, left)
            f_left = np.where(same, f_middle, f_left)
            right = np.where(same[:, None], right, middle)
        found.append(0.5 * (left + right))
    return np.concatenate(found) if found else np.empty((0, 3))


# ------------------------------------------------------------------------------------ output
def spec_table(table: dict[str, dict[str, Range]]) -> str:
    """The spec-sheet table: each quantity, optimum and best sample (m), and the optimum's state."""
    lines = [f"{'quantity':42s} {'optimum':>9s} {'sampled':>9s}   state [swing rad, boom, arm, bucket m]"]
    labels = QUANTITIES | {"bucket_pin_height": "max dumping height (bucket pin)"}
    for key, label in labels.items():
        best, grid = table[key]["optimum"], table[key]["sampled"]
        state = ", ".join(f"{v:.4f}" for v in best.state)
        lines.append(f"{label:42s} {best.value:9.4f} {grid.value:9.4f}   [{state}]")
    return "\n".join(lines)


def as_json(table: dict[str, dict[str, Range]]) -> dict[str, object]:
    """The issue's keys: each {"value", "state", "sampled": {...}}; the dumping height also
    carries ``bucket_pin``."""
    out: dict[str, object] = {}
    for key in QUANTITIES:
        entry = table[key]["optimum"].as_json() | {"sampled": table[key]["sampled"].as_json()}
        if key == "max_dumping_height":
            entry["bucket_pin"] = table["bucket_pin_height"]["optimum"].as_json()
        out[key] = entry
    return out


def draw(ranges: WorkingRanges, table: dict[str, dict[str, Range]], path: Path, samples: int = 61) -> None:
    """The classic side-view envelope: contour of the teeth over the stroke box, the ground, the
    machine at its maximum reach, and each quantity at the point that attains it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy import ndimage

    axes = [np.linspace(ranges.lo[i], ranges.hi[i], samples) for i in range(3)]
    tips = ranges.tip(np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3))
    cell = 0.05  # m: coarse enough that the 61^3 samples fill every cell inside the envelope
    r0, z0 = tips.min(axis=0) - 5 * cell
    index = np.floor((tips - (r0, z0)) / cell).astype(int)
    occupied = np.zeros(index.max(axis=0) + 6, dtype=bool)
    occupied[index[:, 0], index[:, 1]] = True
    occupied = ndimage.binary_fill_holes(ndimage.binary_closing(occupied, iterations=3))
    r_axis = r0 + (np.arange(occupied.shape[0]) + 0.5) * cell
    z_axis = z0 + (np.arange(occupied.shape[1]) + 0.5) * cell

    fig, ax = plt.subplots(figsize=(12, 8))
    ax.contour(r_axis, z_axis, occupied.T.astype(float), levels=[0.5], colors="tab:blue", linewidths=2)
    ax.plot([], [], color="tab:blue", label="contour of the bucket teeth (stroke box)")
    ax.axhline(0.0, color="saddlebrown", linewidth=2, label="ground (z = 0)")
    reach = table["max_digging_reach"]["optimum"].state
    pins = ranges.model.pins(reach)
    chain = ["boom_foot", "arm_pin", "bucket_pin", "bucket_tip"]
    ax.plot(
        [pins[k][0] for k in chain],
        [pins[k][2] + ranges.base_height for k in chain],
        "o-",
        color="0.3",
        label="machine at max digging reach",
    )
    for start, end in (
        ("boom_cylinder_base", "boom_cylinder_rod"),
        ("arm_cylinder_base", "arm_cylinder_rod"),
        ("bucket_cylinder_base", "bucket_cylinder_rod"),
        ("side_link_pivot", "bucket_cylinder_rod"),
        ("bucket_cylinder_rod", "h_link_pin"),
    ):
        heights = [pins[start][2] + ranges.base_height, pins[end][2] + ranges.base_height]
        ax.plot([pins[start][0], pins[end][0]], heights, "-", color="0.55", linewidth=1)
    ax.plot([0, 0], [0, 1.2 * ranges.model.l0], "k-.", linewidth=1, label="swing axis")
    # A shape per quantity, each smaller than the one before and drawn over it: quantities at the
    # same point (the digging depth and the vertical wall's on the CET200) both stay visible.
    for n, (key, label) in enumerate(QUANTITIES.items()):
        best = table[key]["optimum"]
        tip = ranges.tip(best.state[1:])
        point = tip if key != "min_front_swing_radius" else (best.value, tip[1])
        ax.plot(
            *point,
            _MARKERS[n % len(_MARKERS)],
            color=f"C{n + 1}",
            markersize=14 - n,
            markeredgecolor="white",
            markeredgewidth=1.0,
            label=f"{label}: {best.value:.3f} m",
        )
    ax.set_xlabel("r: horizontal distance from the swing axis (m)")
    ax.set_ylabel("height above ground (m)")
    ax.set_title(f"{ranges.model.name}: working ranges from the geometry (optimum over the stroke box)")
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


_MARKERS = ("s", "o", "D", "^", "v", "P", "X")


def main(argv: list[str] | None = None) -> int:
    """``excavator_working_ranges [--params-file FILE] [--json FILE] [--plot PNG]``."""
    from manipulator_kinematics.registry import machine

    parser = argparse.ArgumentParser(prog="excavator_working_ranges", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--params-file", type=Path, help="ROS params file with the excavator (default: CET200)"
    )
    parser.add_argument("--json", type=Path, help="write the table as JSON to this file")
    parser.add_argument("--plot", type=Path, help="write the envelope PNG to this file")
    args = parser.parse_args(argv)
    excavator = machine("excavator")
    try:
        model = excavator.model(args.params_file)
        base_height = excavator.parameters(args.params_file)["base_height"]
    except (ConfigError, OSError) as error:
        print(f"excavator_working_ranges: {error}", file=sys.stderr)
        return 2
    ranges = WorkingRanges(model, base_height)
    table = ranges.table()
    print(spec_table(table))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(as_json(table), indent=2, default=float) + "\n")
    if args.plot is not None:
        draw(ranges, table, args.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
