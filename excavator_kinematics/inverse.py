"""Pose IK of the excavator, closed form: every D = [theta1, d2, d3, d4] that puts the bucket at a
target, each with a status, and the one the shared rule selects (numpy only).

The inverse of paper eq. 3 (the open chain), then of eqs. 1-2 (the cylinder linkages):

1. swing: the tip lies in the boom plane, so theta1 = atan2(y, x) with the tip in front of the
   swing axis (boom-plane radius rho = r), or theta1 + pi with the tip behind it (rho = -r);
2. the bucket pin is the tip less l4 (cos alpha, sin alpha) in the boom plane; boom and arm are
   the planar 2R arm (l2, l3) from the boom foot pin [l1, l0] to it
   (:func:`manipulator_kinematics.planar.two_link_ik`): elbow up (theta3 <= 0, how an excavator
   is built) and elbow down (theta3 >= 0);
3. theta4 = alpha - theta2 - theta3 (eq. 3: alpha = theta2 + theta3 + theta4);
4. the cylinder lengths of theta2..theta4 (:meth:`Excavator.linkage_lengths`, the closed form of
   :meth:`Excavator.cylinder_lengths`).

Candidates (..., 4, 4) in :data:`BRANCHES` order; statuses by the shared
:func:`manipulator_kinematics.model.limit_status`: SUCCESS inside the stroke box and the swing
range, JOINT_LIMITS outside a stroke, UNREACHABLE where the bucket pin is out of the boom and
arm's reach or a linkage cannot close at that angle (no length of its cylinder gives it), SINGULAR
with the tip on the swing axis (any swing reaches it; JC0 is singular there). The shared
:func:`manipulator_kinematics.model.select` picks one: of the SUCCESS candidates the one of a
requested branch, else the one closest to the seed (each actuator's distance divided by its range,
so radians and metres weigh alike), else the first in branch order.

Position only (mode ``position``): the bucket angle alpha is free. It is the seed's (alpha of the
seed's pose, the seed first moved into the limits), else for each branch the angle with the
largest stroke margin: max over alpha of min over the three cylinders of the distance to the
nearer stroke end as a fraction of the stroke (on a 1 deg grid, refined four times tenfold, so to
within 2e-6 rad).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.model import (
    IKSolutions,
    IKStatus,
    RequestError,
    describe_limits,
    limit_status,
    select,
)
from manipulator_kinematics.planar import ELBOW_NEGATIVE, ELBOW_POSITIVE, two_link_ik, wrap_angle

if TYPE_CHECKING:
    from excavator_kinematics.kinematics import Excavator

#: Candidate order = preference order without a seed.
BRANCHES = ("front_elbow_up", "front_elbow_down", "behind_elbow_up", "behind_elbow_down")
#: ``pose``: position and bucket angle; ``position``: position only (module docstring).
MODES = ("pose", "position")
#: A tip closer to the swing axis than this (m) has no defined swing: SINGULAR.
SWING_AXIS = 1e-9
#: A 6-D target counts as in its boom plane / with a level bucket pin axis within this (m, rad).
PLANE_TOL = 1e-9
# Stroke-margin search of the position mode: a grid over a full turn, then ``_REFINE`` levels of
# ``2 * _POINTS`` steps of a tenth of the previous step each side of the best angle.
_GRID = 360
_REFINE = 4
_POINTS = 10
_ELBOWS = (ELBOW_NEGATIVE, ELBOW_POSITIVE)  # two_link_ik's branch index of elbow up, elbow down
_SUCCESS, _SINGULAR, _UNREACHABLE = int(IKStatus.SUCCESS), int(IKStatus.SINGULAR), int(IKStatus.UNREACHABLE)


def open_chain_candidates(model: Excavator, Q: np.ndarray,
                          heading: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Every open-chain theta = [theta1..theta4] with eq. 3's Q(theta) = Q (..., 4), steps 1-3 of
    the module docstring: (theta (..., 4, 4) in BRANCHES order, NaN where the bucket pin is out
    of the arm's reach; reach (..., 4) of :class:`manipulator_kinematics.planar.Reach`).

    ``heading`` (...,): the swing of the first two candidates (a 6-D target's boom plane); the tip
    then lies at the signed radius x cos + y sin of it. Default atan2(y, x), the tip in front.
    """
    x, y, z, alpha = np.moveaxis(Q, -1, 0)
    if heading is None:
        heading = np.arctan2(y, x)
    swing = np.stack((heading, wrap_angle(heading + np.pi)), axis=-1)  # (..., 2)
    rho = x * np.cos(heading) + y * np.sin(heading)
    rho = np.stack((rho, -rho), axis=-1)
    # Bucket pin relative to the boom foot pin, in the boom plane of each swing.
    pin_r = rho - model.l4 * np.cos(alpha)[..., None] - model.l1
    pin_z = (z - model.l4 * np.sin(alpha) - model.l0)[..., None]
    arm = two_link_ik(pin_r, pin_z, model.l2, model.l3)  # theta1, theta2: (..., 2 swings, 2 elbows)
    theta2, theta3 = arm.theta1[..., _ELBOWS], arm.theta2[..., _ELBOWS]
    theta4 = alpha[..., None, None] - theta2 - theta3
    swing = np.broadcast_to(swing[..., None], theta2.shape)
    shape = Q.shape[:-1] + (4,)
    theta = np.stack((swing, theta2, theta3, theta4), axis=-1).reshape(shape + (4,))
    return theta, np.broadcast_to(arm.reach[..., None], theta2.shape).reshape(shape)


def candidates(model: Excavator, Q: np.ndarray, heading: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """Every D reaching Q = [x, y, z, alpha] (..., 4): (D (..., 4, 4), reach (..., 4)), the
    open-chain candidates turned into cylinder lengths; NaN where there is no solution."""
    theta, reach = open_chain_candidates(model, Q, heading)
    D = np.concatenate((theta[..., :1], model.linkage_lengths(theta[..., 1:])), axis=-1)
    return D, reach


def status(model: Excavator, D: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """(..., 4) IKStatus of candidates D (..., 4, 4) of targets Q (..., 4) (module docstring)."""
    judged = limit_status(D, model.joint_limits)
    on_axis = np.hypot(Q[..., 0], Q[..., 1]) <= SWING_AXIS
    return np.where(on_axis[..., None] & (judged == _SUCCESS), _SINGULAR, judged).astype(np.int8)


def _branch_index(branch: str | None) -> int | None:
    if branch is None:
        return None
    if branch not in BRANCHES:
        raise RequestError(f"unknown branch {branch!r}; known: {', '.join(BRANCHES)} "
                           "(empty = closest to the seed)")
    return BRANCHES.index(branch)


def _solutions(model: Excavator, Q: np.ndarray, D: np.ndarray, reach: np.ndarray, judged: np.ndarray,
               seed: np.ndarray | None, branch: int | None, other_heading: bool = False) -> IKSolutions:
    """IKSolutions of candidates D (..., 4, 4) of targets Q (..., 4, 4) (one per candidate) with
    statuses ``judged``; ``other_heading``: the last two candidates are refused for facing the
    other way (a 6-D target)."""
    weights = 1.0 / (model.joint_limits.upper - model.joint_limits.lower)
    selected, tie = select(D, judged, seed=seed, branch=branch, weights=weights)

    def explain(solutions: IKSolutions, index: tuple[int, ...]) -> str:
        chosen = int(solutions.selected[index])
        if chosen >= 0:
            rule = ("the requested branch" if branch is not None else
                    "closest to the seed" if seed is not None else "first valid in branch order")
            tie = " (tie: another valid solution is as close to the seed)" if solutions.tie[index] else ""
            return f"branch {BRANCHES[chosen]} ({rule}){tie}"
        parts = []
        for i, name in enumerate(BRANCHES):
            if branch is not None and i != branch:
                continue
            if other_heading and i >= 2:
                note = "the swing of the other heading turns the bucket frame half a turn from the target's"
            else:
                note = _candidate_note(model, Q[index][i], D[index][i], int(reach[index][i]),
                                       int(judged[index][i]))
            parts.append(f"{name}: {note}")
        return "no valid solution: " + "; ".join(parts)

    return IKSolutions(q=D, status=judged, branches=BRANCHES, selected=selected, tie=tie, explain=explain)


def _candidate_note(model: Excavator, Q: np.ndarray, D: np.ndarray, reach: int, judged: int) -> str:
    if judged == _SINGULAR:
        return "the tip is on the swing axis (any swing angle, JC0 singular)"
    if judged == int(IKStatus.JOINT_LIMITS):
        return f"outside a stroke ({describe_limits(D, model.joint_limits)})"
    if judged == int(IKStatus.INVALID):
        return "the target is not finite"
    if reach != 0:
        return f"the bucket pin is out of the boom and arm's reach ({_pin_reach(model, Q, D)})"
    linkages = ("boom cylinder", "arm cylinder", "bucket linkage")
    closing = [name for name, d in zip(linkages, D[1:], strict=True) if math.isnan(d)]
    return f"the {', '.join(closing)} cannot close at this angle (no length gives it)"


def _pin_reach(model: Excavator, Q: np.ndarray, D: np.ndarray) -> str:
    r = Q[0] * math.cos(D[0]) + Q[1] * math.sin(D[0]) - model.l4 * math.cos(Q[3]) - model.l1
    distance = math.hypot(r, Q[2] - model.l4 * math.sin(Q[3]) - model.l0)
    return (f"{distance:.6g} m from the boom foot pin, the arm reaches "
            f"[{abs(model.l2 - model.l3):.6g}, {model.l2 + model.l3:.6g}] m")


def _seed(seed: ArrayLike | None) -> np.ndarray | None:
    return None if seed is None else np.asarray(seed, dtype=float)


def solve_pose(model: Excavator, Q: ArrayLike, seed: ArrayLike | None = None,
               branch: str | None = None) -> IKSolutions:
    """Every candidate for targets Q = [x, y, z, alpha] (..., 4) and the selected one."""
    index = _branch_index(branch)
    Q = np.asarray(Q, dtype=float)
    if Q.shape[-1:] != (4,):
        raise ValueError(f"expected Q = [x, y, z, alpha] of shape (..., 4), got shape {Q.shape}")
    finite = np.all(np.isfinite(Q), axis=-1)
    with np.errstate(invalid="ignore"):
        D, reach = candidates(model, Q)
    judged = status(model, D, Q)
    judged[~finite] = int(IKStatus.INVALID)
    return _solutions(model, np.broadcast_to(Q[..., None, :], D.shape), D, reach, judged, _seed(seed), index)


def seed_bucket_angle(model: Excavator, seed: ArrayLike) -> np.ndarray:
    """alpha of the seed's pose, the seed first moved into the limits (it is a hint, not a state)."""
    seed = model.joint_limits.clip(np.asarray(seed, dtype=float))
    return model.pose(seed.reshape(-1, 4))[:, 3].reshape(seed.shape[:-1])


def widest_margin_angles(model: Excavator, position: np.ndarray) -> np.ndarray:
    """(..., 4) per branch the bucket angle with the largest stroke margin at ``position`` (..., 3)
    (module docstring); NaN-free: a branch without any solution gets -pi."""
    grid = np.linspace(-np.pi, np.pi, _GRID, endpoint=False)
    alpha = np.broadcast_to(grid[:, None], position.shape[:-1] + (_GRID, 4))  # (..., G, branch)
    step = grid[1] - grid[0]
    offsets = np.arange(-_POINTS, _POINTS + 1) / _POINTS
    for level in range(_REFINE + 1):
        margin = _branch_margins(model, position, alpha)  # (..., k, branch)
        best = np.take_along_axis(alpha, np.argmax(margin, axis=-2)[..., None, :], axis=-2)[..., 0, :]
        if level < _REFINE:
            alpha = best[..., None, :] + step * offsets[:, None]
            step = step / _POINTS
    return best


def _branch_margins(model: Excavator, position: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Stroke margins (..., k, 4) of branch b's candidate at bucket angle alpha[..., k, b]."""
    Q = np.concatenate(
        (np.broadcast_to(position[..., None, None, :], alpha.shape + (3,)), alpha[..., None]), axis=-1
    )  # (..., k, branch, 4)
    with np.errstate(invalid="ignore"):
        D, _ = candidates(model, Q)  # (..., k, branch, candidate, 4)
    mine = np.arange(4)
    lengths = D[..., mine, mine, 1:]  # candidate b of the target built for branch b
    limits = model.limits
    margin = np.minimum(lengths - limits.stroke_min, limits.stroke_max - lengths) / (
        limits.stroke_max - limits.stroke_min)
    margin = np.min(margin, axis=-1)
    return np.where(np.isnan(margin), -np.inf, margin)


def solve_position(model: Excavator, position: ArrayLike, seed: ArrayLike | None = None,
                   branch: str | None = None) -> IKSolutions:
    """Every candidate for tip positions (..., 3), the bucket angle free (module docstring)."""
    index = _branch_index(branch)
    position = np.asarray(position, dtype=float)
    if position.shape[-1:] != (3,):
        raise ValueError(f"expected a position [x, y, z] of shape (..., 3), got shape {position.shape}")
    finite = np.all(np.isfinite(position), axis=-1)
    seed = _seed(seed)
    if seed is not None:
        alpha = np.broadcast_to(seed_bucket_angle(model, seed), position.shape[:-1])
        Q = np.concatenate((position, alpha[..., None]), axis=-1)
        with np.errstate(invalid="ignore"):
            D, reach = candidates(model, Q)
        Q = np.broadcast_to(Q[..., None, :], D.shape)
    else:
        alpha = widest_margin_angles(model, np.where(finite[..., None], position, 0.0))
        at = np.broadcast_to(position[..., None, :], alpha.shape + (3,))
        Q = np.concatenate((at, alpha[..., None]), axis=-1)
        with np.errstate(invalid="ignore"):
            D, reach = candidates(model, Q)  # (..., branch, candidate, 4): keep candidate == branch
        mine = np.arange(4)
        D, reach = D[..., mine, mine, :], reach[..., mine, mine]
    judged = status(model, D, Q[..., 0, :])
    judged[~finite] = int(IKStatus.INVALID)
    return _solutions(model, Q, D, reach, judged, seed, index)


def bucket_rotation(theta1: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """R = Rz(theta1) Ry(-alpha) (..., 3, 3): the bucket frame (docs/excavator.md, Frames)."""
    c1, s1, ca, sa = np.cos(theta1), np.sin(theta1), np.cos(alpha), np.sin(alpha)
    zero = np.zeros_like(c1)
    return np.stack([
        np.stack([c1 * ca, -s1, -c1 * sa], axis=-1),
        np.stack([s1 * ca, c1, -s1 * sa], axis=-1),
        np.stack([sa, zero, ca], axis=-1),
    ], axis=-2)


def fkine(model: Excavator, D: ArrayLike) -> np.ndarray:
    """Bucket pose (..., 4, 4) in the base frame for D (..., 4) (eqs. 1-3; StrokeError outside
    the limits)."""
    D = np.asarray(D, dtype=float)
    Q = model.pose(D.reshape(-1, 4)).reshape(D.shape)
    pose = np.zeros(D.shape[:-1] + (4, 4))
    pose[..., :3, :3] = bucket_rotation(D[..., 0], Q[..., 3])
    pose[..., :3, 3] = Q[..., :3]
    pose[..., 3, 3] = 1.0
    return pose


def jacob0(model: Excavator, D: ArrayLike) -> np.ndarray:
    """(..., 6, 4): bucket twist [v; omega] = jacob0 Ddot; v = JC0's first rows (eq. 8), omega =
    theta1dot z - alphadot y' (docs/excavator.md, bucket twist)."""
    D = np.asarray(D, dtype=float)
    jc0 = model.jc0(D.reshape(-1, 4)).reshape(D.shape[:-1] + (4, 4))
    c1, s1 = np.cos(D[..., 0])[..., None], np.sin(D[..., 0])[..., None]
    swing = np.broadcast_to(np.array([1.0, 0.0, 0.0, 0.0]), jc0.shape[:-2] + (4,))
    angular = np.stack((s1 * jc0[..., 3, :], -c1 * jc0[..., 3, :], swing), axis=-2)
    return np.concatenate((jc0[..., :3, :], angular), axis=-2)


def solve_ik(model: Excavator, target: ArrayLike, *, use_orientation: bool = True, mode: str | None = None,
             seed: ArrayLike | None = None, branch: str | None = None) -> IKSolutions:
    """The SerialModel entry (SolveIK): target poses (..., 4, 4) in the base frame.

    Mode ``pose`` (default with an orientation): the orientation gives the swing heading (the
    bucket frame's y axis is the boom-plane normal) and alpha; a target whose y axis is not level
    or whose position is off that boom plane is UNREACHABLE, and so are the two candidates of the
    other heading (their bucket frame is turned half a turn). Mode ``position`` (default without):
    :func:`solve_position`.
    """
    mode = mode or ("pose" if use_orientation else "position")
    if mode not in MODES:
        raise RequestError(f"unknown mode {mode!r}; known: {', '.join(MODES)}")
    index = _branch_index(branch)
    if mode == "pose" and not use_orientation:
        raise RequestError("mode 'pose' takes the bucket angle from the target orientation: set "
                           "use_orientation", IKStatus.INVALID)
    if mode == "position" and use_orientation:
        raise RequestError("mode 'position' leaves the bucket angle free: use mode 'pose' to give an "
                           "orientation", IKStatus.INVALID)
    target = np.asarray(target, dtype=float)
    position = target[..., :3, 3]
    if mode == "position":
        return solve_position(model, position, seed, branch)
    R = target[..., :3, :3]
    finite = np.all(np.isfinite(target), axis=(-2, -1))
    heading = np.arctan2(-R[..., 0, 1], R[..., 1, 1])
    alpha = np.arctan2(R[..., 2, 0], R[..., 2, 2])
    rolled = np.abs(R[..., 2, 1]) > PLANE_TOL
    lateral = -position[..., 0] * np.sin(heading) + position[..., 1] * np.cos(heading)
    off_plane = np.abs(lateral) > PLANE_TOL
    Q = np.concatenate((position, alpha[..., None]), axis=-1)
    with np.errstate(invalid="ignore"):
        D, reach = candidates(model, Q, heading)
    judged = status(model, D, Q)
    judged[..., 2:] = _UNREACHABLE  # the other heading: not this orientation
    judged[rolled | off_plane] = _UNREACHABLE
    judged[~finite] = int(IKStatus.INVALID)
    solutions = _solutions(model, np.broadcast_to(Q[..., None, :], D.shape), D, reach, judged,
                           _seed(seed), index, other_heading=True)

    def explain(result: IKSolutions, where: tuple[int, ...]) -> str:
        if not finite[where]:
            return "target is not finite"
        if rolled[where]:
            roll = math.degrees(math.asin(min(1.0, abs(float(R[where][2, 1])))))
            return (f"target orientation rolls the bucket by {roll:.6g} deg: its y axis (the boom-plane "
                    "normal) must be level")
        if off_plane[where]:
            return (f"target position is {float(lateral[where]):.6g} m off the boom plane of the "
                    f"orientation's heading {math.degrees(float(heading[where])):.6g} deg")
        return solutions.explain(result, where)

    return IKSolutions(q=D, status=judged, branches=BRANCHES, selected=solutions.selected, tie=solutions.tie,
                       explain=explain)
