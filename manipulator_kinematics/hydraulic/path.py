"""Straight tool-point lines through waypoints for any machine of the hydraulic family, timed
within its actuators' speed limits (numpy only): ``plan_path`` of ``hydraulic_ik_server``.

1. The state the path starts from: the seed (the true state D, moved into the stroke box), else
   the machine file's reference state. What the tool point does not fix is held from it along
   the whole path, as :meth:`~manipulator_kinematics.hydraulic.model.HydraulicModel.position_ik`
   holds it: the tool angle where the main chain has a third revolute joint (an excavator), the
   extension where it ends in a prismatic joint (the knuckle crane's telescope); the loader's two
   actuators are fixed by (x, z) alone, its bucket angle follows, and without a swing the tool
   point stays in the x-z plane (y = 0).
2. The first waypoint is solved from that state (closed form, the solution nearest it); the shared
   walk (:func:`manipulator_kinematics.tool_path.walk_lines`) samples each straight line every
   ``step`` and every sample is solved with the same hold. A sample no state inside the stroke
   box reaches (solved nearest the state before it, so the path keeps the branch it starts on),
   or reached only by a jump from its neighbour (the swing by more than
   :data:`MAX_SWING_STEP`, a cylinder by more than :data:`MAX_STROKE_STEP` of its stroke: another
   branch or the line passing the swing axis), ends the path at the farthest reachable point of
   the line, with the reason (the actuator at its stroke end there, or the linkage's reach) and
   the last waypoint reached in full.
3. The samples are timed by the shared walk (no actuator above its ``max_speed``, the tool point
   not above ``tip_speed``, its acceleration along the path at most ``acceleration``, at rest at
   both ends and at every corner); :func:`plan_clear` ends a path before an avoidance zone
   (:func:`manipulator_kinematics.tool_path.clear_of_zones`, the points of
   :meth:`~manipulator_kinematics.hydraulic.model.HydraulicModel.monitored`).

D here is the true state (strokes as in the machine file); the node turns it into sensor
readings (D - zero_offset) and back.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.hydraulic.model import HydraulicModel, IKResult
from manipulator_kinematics.plan_bounds import check_plan
from manipulator_kinematics.tool_path import ToolPlan, clear_of_zones, show, walk_lines
from manipulator_kinematics.zones import Zone

#: A swing change between neighbouring samples above this (rad) is a line passing the swing axis
#: (the excavator's rule, :data:`excavator_kinematics.core.path.MAX_SWING_STEP`).
MAX_SWING_STEP = 0.5
#: A cylinder change between neighbouring samples above this fraction of its stroke is a jump to
#: another branch of the linkage, not a motion along the line.
MAX_STROKE_STEP = 0.5


def _held(h: HydraulicModel, start: np.ndarray) -> str:
    """What the path holds from ``start``, for the message (module docstring, step 1)."""
    d = h.description
    revolute = sum(j.slide is None for j in d.joints)
    if d.has_angle and revolute > 2:
        return f", tool angle {np.degrees(h.pose(start)[3]):.6g} deg held"
    slides = [j.slide for j in d.joints if j.slide is not None]
    if slides:
        return f", {h.actuator_names[slides[0].index]} held at {start[slides[0].index]:.6g} m"
    return ""


#: Samples solved from one seed, the state before them (a bound on the work a branch change costs).
BLOCK = 256
#: An actuator this close to a stroke end (fraction of its range) at the end of a reachable line
#: is the reason the line ends there.
AT_END = 1e-3


def _unreached(h: HydraulicModel, point: np.ndarray) -> str:
    """A point no state reaches, and where the machine has no swing, its plane."""
    text = f"no state inside the stroke box reaches {show(point)}"
    if h.swing or abs(point[1]) <= 1e-9:
        return text
    return f"{text} (no swing: the tool stays at y = 0, not {point[1]:.4g})"


def _stop(h: HydraulicModel, near: np.ndarray) -> str:
    """What stops the tool at the state ``near``: an actuator at its stroke end, or the reach."""
    margin = np.minimum(near - h.lower, h.upper - near) / (h.upper - h.lower)
    i = int(np.argmin(margin))
    if margin[i] > AT_END:
        return "beyond the linkage's reach there (no actuator at a stroke end)"
    end = "min" if near[i] - h.lower[i] <= h.upper[i] - near[i] else "max"
    unit = "rad" if h.swing and i == 0 else "m"
    return f"{h.actuator_names[i]} at its {end} stroke ({near[i]:.6g} {unit})"


def _solve(h: HydraulicModel, points: np.ndarray, seed: np.ndarray, alpha: float | None) -> IKResult:
    """D of ``points`` (N, 3) nearest ``seed``: the tool angle ``alpha`` held where it is given,
    else what :meth:`~manipulator_kinematics.hydraulic.model.HydraulicModel.position_ik` holds
    from the seed (the extension of a telescope)."""
    seeds = np.broadcast_to(seed, (len(points), h.m))
    if alpha is None:
        return h.position_ik(points, seeds)
    return h.ik(np.column_stack((points, np.full(len(points), alpha))), seeds)


def _solve_line(
    h: HydraulicModel, line: np.ndarray, previous: np.ndarray, alpha: float | None, jump: np.ndarray
) -> tuple[np.ndarray, int | None, str]:
    """D of every sample after the state ``previous``, in blocks of :data:`BLOCK` samples, each
    nearest the state before it; where a sample is not reached from there, or only by a jump,
    the rest of its block is solved again nearest the sample before it (two branches may both
    reach the line, the loader's tilt: the path keeps the one it follows). The first sample that
    fails even so (None: all pass) and why."""
    D = np.full((len(line), h.m), np.nan)
    k = 0
    while k < len(line):
        before = previous if k == 0 else D[k - 1]
        end = min(k + BLOCK, len(line))
        D[k:end] = _solve(h, line[k:end], before, alpha).D  # NaN where not reached
        steps = np.abs(np.diff(np.vstack((before, D[k:end])), axis=0))
        failed = ~np.all(steps <= jump, axis=1)  # NaN (no solution) counts as a jump too
        if failed[0]:  # not even from its neighbour
            bad = k
            break
        k = k + int(np.argmax(failed)) if failed.any() else end
    else:
        return D, None, ""
    near = previous if bad == 0 else D[bad - 1]
    if np.all(np.isfinite(D[bad])):
        i = int(np.argmax(steps[0] / jump))
        return (
            D,
            bad,
            f"{h.actuator_names[i]} would jump by {steps[0, i]:.4g} between samples (another branch of "
            f"the linkage, or the line passes the swing axis); {_stop(h, near)}",
        )
    return D, bad, f"{_unreached(h, line[bad])}: {_stop(h, near)}"


def plan_path(
    h: HydraulicModel,
    waypoints: ArrayLike,
    step: float,
    tip_speed: float,
    acceleration: float,
    seed: ArrayLike | None = None,
) -> ToolPlan:
    """Plan through ``waypoints`` (K, 3) from the true state ``seed`` (module docstring).
    ValueError for a request beyond the bounds of every machine's plan
    (:func:`manipulator_kinematics.plan_bounds.check_plan`)."""
    waypoints = check_plan(waypoints, step, tip_speed, acceleration)
    start = h.reference if seed is None else np.clip(np.asarray(seed, dtype=float), h.lower, h.upper)
    first = h.position_ik(waypoints[0], start)
    if not bool(first.valid):
        text = f"the first waypoint is not reachable: {_unreached(h, waypoints[0])}"
        return ToolPlan(waypoints[:0], None, True, -1, text)
    jump = MAX_STROKE_STEP * (h.upper - h.lower)
    if h.swing:
        jump[0] = MAX_SWING_STEP
    held = h.description.has_angle and sum(j.slide is None for j in h.description.joints) > 2
    alpha = float(h.pose(first.D)[3]) if held else None
    return walk_lines(
        waypoints,
        first.D,
        step,
        lambda line, previous: _solve_line(h, line, previous, alpha, jump),
        h.max_speed,
        h.actuator_names,
        tip_speed,
        acceleration,
        _held(h, first.D),
    )


def plan_clear(
    h: HydraulicModel,
    zones: Sequence[Zone],
    waypoints: ArrayLike,
    step: float,
    tip_speed: float,
    acceleration: float,
    seed: ArrayLike | None = None,
) -> ToolPlan:
    """:func:`plan_path` ended before the first avoidance zone a monitored point would enter
    (:func:`manipulator_kinematics.tool_path.clear_of_zones`; base-frame zones)."""
    names = h.monitored(h.reference, np.zeros(h.m))[0]
    return clear_of_zones(
        lambda through: plan_path(h, through, step, tip_speed, acceleration, seed),
        np.asarray(waypoints, dtype=float).reshape(-1, 3),
        zones,
        names,
        lambda D: h.monitored(D, np.zeros_like(D))[1],
    )
