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
nearer stroke end as a fraction of the stroke (:func:`widest_margin_angles`: the three best local
maxima of a 2.5 deg grid, each refined to within 2e-8 rad; a feasible band of alpha narrower
than the grid step can be missed).

Speed: the numpy path runs a batch vectorised in blocks of rows
(:func:`manipulator_kinematics.row_blocks.in_blocks`), the machine's numbers folded once
(:class:`Constants`); one target and a batch of :func:`solve_pose` run the same steps compiled
(:mod:`excavator_kinematics.core.ik_kernel`, numba), the numpy path staying the reference
(``compiled=False``). benchmarks/bench_excavator_ik.py measures both against scipy's least squares.
"""

from __future__ import annotations

import math
from types import ModuleType
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from excavator_kinematics.core.geometry import cos_sin
from excavator_kinematics.core.layouts import IK, check_compiled
from excavator_kinematics.core.machine_file import STROKE_TOLERANCE, wrap_swing
from manipulator_kinematics.compiled import Kernel
from manipulator_kinematics.model import (
    TIE_TOLERANCE,
    IKSolutions,
    IKStatus,
    RequestError,
    describe_limits,
    limit_status,
    select,
)
from manipulator_kinematics.planar import Reach, wrap_angle
from manipulator_kinematics.row_blocks import BLOCK, in_blocks

if TYPE_CHECKING:
    from excavator_kinematics.core.kinematics import Excavator

#: Candidate order = preference order without a seed.
BRANCHES = ("front_elbow_up", "front_elbow_down", "behind_elbow_up", "behind_elbow_down")
#: ``pose``: position and bucket angle; ``position``: position only (module docstring).
MODES = ("pose", "position")
#: A tip closer to the swing axis than this (m) has no defined swing: SINGULAR.
SWING_AXIS = 1e-9
#: A candidate this far (m, rad) outside a limit is inside (model.limit_status' tolerance).
LIMIT_TOL = 1e-10
#: A 6-D target counts as in its boom plane / with a level bucket pin axis within this (m, rad).
PLANE_TOL = 1e-9
_SUCCESS, _SINGULAR, _UNREACHABLE = int(IKStatus.SUCCESS), int(IKStatus.SINGULAR), int(IKStatus.UNREACHABLE)
_INVALID = int(IKStatus.INVALID)
_NO_SEEDS = np.zeros((1, 4))  # a batch's without one (ik_kernel.solve_batch reads its row, never uses it)
_REACHABLE, _TOO_FAR, _TOO_CLOSE, _NOT_FINITE = (int(r) for r in Reach)  # in Reach's order
# Stroke-margin search of the position mode (widest_margin_angles): golden-section steps shrink
# the bracket of 2 grid steps to 4 pi / _GRID * _GOLDEN**_GOLDEN_STEPS = 1.8e-8 rad.
_GRID = 144
_PEAKS = 3
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
_GOLDEN_STEPS = 32


class Constants(NamedTuple):
    """The machine's numbers the IK reads, as Python floats, folded once per machine
    (:meth:`Excavator.__init__`): a call recomputes nothing from the geometry."""

    l0: float
    l1: float
    l2: float
    l3: float
    l4: float
    l2l2_l3l3: float  # l2^2 + l3^2
    two_l2l3: float
    reach_max: float  # l2 + l3 + the planar arm's tolerance
    reach_min: float  # |l2 - l3| - that tolerance
    # Boom and arm triangles (eq. 1): d^2 = a^2 + b^2 - 2ab cos gamma, gamma = o (theta - offset).
    boom_o: float
    boom_offset: float
    boom_aa_bb: float
    boom_two_ab: float
    arm_o: float
    arm_offset: float
    arm_aa_bb: float
    arm_two_ab: float
    # Bucket linkage (eq. 2 backwards): the H-link pin H on its circle about the bucket pin, the
    # rod pin R on the side-link circle about the pivot; vectors relative to the pivot.
    h_phase: float
    h_radius: float
    pin_from_pivot_x: float  # bucket pin - pivot
    pin_from_pivot_y: float
    base_from_pivot_x: float  # bucket cylinder base pin - pivot
    base_from_pivot_y: float
    side: float
    side_hh: float  # side^2 - h_link^2
    two_side: float
    side_o: float
    h_o: float
    stroke_lo: float  # bucket stroke with the stroke tolerance
    stroke_hi: float
    stroke_min: np.ndarray  # (3,) the strokes, for the stroke margin
    stroke_max: np.ndarray
    stroke_range: np.ndarray
    weights: np.ndarray  # (4,) 1 / range of each actuator: the seed distance of model.select
    # The constants of the compiled kernel (ik_kernel), layout ``layouts.IK``: the float fields
    # above, the limits widened by limit_status' tolerance, the weights and the strokes.
    packed: np.ndarray

    @classmethod
    def of(cls, model: Excavator, arm_tol: float = 1e-12) -> Constants:
        linkages = model.linkages
        boom, arm = linkages.boom, linkages.arm
        pivot, pin, base = linkages.pivot, linkages.bucket_pin, linkages.bucket_cylinder_base
        side, stroke = linkages.side_link, (model.limits.stroke_min[2], model.limits.stroke_max[2])
        k = cls(
            model.l0,
            model.l1,
            model.l2,
            model.l3,
            model.l4,
            model.l2**2 + model.l3**2,
            2.0 * model.l2 * model.l3,
            model.l2 + model.l3 + arm_tol,
            abs(model.l2 - model.l3) - arm_tol,
            float(boom.orientation),
            boom.offset,
            boom.a**2 + boom.b**2,
            2.0 * boom.a * boom.b,
            float(arm.orientation),
            arm.offset,
            arm.a**2 + arm.b**2,
            2.0 * arm.a * arm.b,
            linkages.h_phase,
            linkages.h_radius,
            float(pin[0] - pivot[0]),
            float(pin[1] - pivot[1]),
            float(base[0] - pivot[0]),
            float(base[1] - pivot[1]),
            side,
            side**2 - linkages.h_link**2,
            2.0 * side,
            float(linkages.side.orientation),
            float(linkages.h_orientation),
            stroke[0] - STROKE_TOLERANCE,
            stroke[1] + STROKE_TOLERANCE,
            model.limits.stroke_min,
            model.limits.stroke_max,
            model.limits.stroke_max - model.limits.stroke_min,
            1.0 / (model.joint_limits.upper - model.joint_limits.lower),
            np.empty(0),
        )
        lower, upper = model.joint_limits.lower - LIMIT_TOL, model.joint_limits.upper + LIMIT_TOL
        # By name: every other field of the layout is the Constants field of that name.
        limits = {"lower": lower, "upper": upper}
        return k._replace(packed=IK.pack({f: limits[f] if f in limits else getattr(k, f) for f in IK.sizes}))


# Per candidate in BRANCHES order: the sign of the boom-plane radius (the tip in front of or
# behind the swing axis) and of the elbow angle beta added to the boom angle (elbow up: theta3 <= 0).
_RADIUS_SIGN = np.array([1.0, 1.0, -1.0, -1.0])
_SWING_SIGN = np.array([1.0, -1.0])  # the same per swing (front, behind)
_ELBOW_SIGN = np.array([1.0, -1.0, 1.0, -1.0])


def open_chain_columns(
    k: Constants, x: np.ndarray, y: np.ndarray, z: np.ndarray, alpha: np.ndarray, heading: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Steps 1-3 of the module docstring on flat targets: x, y, z, heading (N, 1), alpha (N, 1)
    or (N, 4) (one per candidate): (theta2, theta3, theta4, reach), each (N, 4) in BRANCHES
    order, NaN where the bucket pin is out of the arm's reach (reach of
    :class:`manipulator_kinematics.planar.Reach`).

    With one alpha per target, the arm is solved once per swing (N, 2), both elbows from it.
    """
    per_swing = alpha.shape[-1] == 1
    ch, sh = cos_sin(heading)
    rho = (x * ch + y * sh) * (_SWING_SIGN if per_swing else _RADIUS_SIGN)
    # Bucket pin relative to the boom foot pin, in the boom plane of each swing.
    ca, sa = cos_sin(alpha)
    pin_r = rho - k.l4 * ca - k.l1
    pin_z = z - k.l4 * sa - k.l0
    # The planar 2R arm (l2, l3) to the pin, as manipulator_kinematics.planar.two_link_ik.
    r = np.hypot(pin_r, pin_z)
    reach = np.where(r > k.reach_max, _TOO_FAR, np.where(r < k.reach_min, _TOO_CLOSE, _REACHABLE))
    reach = np.where(np.isfinite(r), reach, _NOT_FINITE).astype(np.int8)
    cos_elbow = np.where(reach == _REACHABLE, np.clip((r * r - k.l2l2_l3l3) / k.two_l2l3, -1.0, 1.0), np.nan)
    elbow = np.arccos(cos_elbow)
    sin_elbow = np.sqrt(1.0 - cos_elbow * cos_elbow)  # sin(arccos c)
    beta = np.arctan2(k.l3 * sin_elbow, k.l2 + k.l3 * cos_elbow)
    base = np.arctan2(pin_z, pin_r)
    if per_swing:  # (N, 2) -> (N, 4): both elbows of each swing
        base, beta, elbow, reach = (np.repeat(v, 2, axis=-1) for v in (base, beta, elbow, reach))
    theta2 = base + _ELBOW_SIGN * beta
    theta3 = -_ELBOW_SIGN * elbow
    theta4 = alpha - theta2 - theta3  # eq. 3: alpha = theta2 + theta3 + theta4
    return theta2, theta3, theta4, reach


def _triangle_length(theta: np.ndarray, o: float, offset: float, aa_bb: float, two_ab: float) -> np.ndarray:
    """Eq. 1's second line: the cylinder length of joint angle theta, NaN off the assembly
    (the triangle closes for gamma = o (theta - offset) in (0, pi) modulo 2 pi).

    By the half angle t = tan(gamma / 2): gamma is in (0, pi) where t > 0, and
    cos gamma = (1 - t^2) / (1 + t^2) (one vectorised tan instead of a remainder and a cos).
    """
    t = o * np.tan(0.5 * (theta - offset))
    tt = t * t
    return np.where(t > 0.0, np.sqrt(aa_bb - two_ab * (1.0 - tt) / (1.0 + tt)), np.nan)


def linkage_length_columns(
    k: Constants, theta2: np.ndarray, theta3: np.ndarray, theta4: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cylinder lengths d2, d3, d4 of joint angles (any one shape), NaN where a linkage cannot
    close (:meth:`Excavator.linkage_lengths`).

    Bucket (eq. 2 backwards): H = bucket pin + h_radius (cos, sin)(theta4 + H phase); the rod pin R
    is where the side-link circle about the pivot meets the H-link circle about H, turned by
    +-spread from the pivot-to-H direction (cos spread = c by the law of cosines); of the two, the
    one on the forward model's assembly (R on the side triangle's branch about the pivot, H on the
    bucket four-bar's branch about the bucket pin), the one inside the stroke where both are.
    """
    d2 = _triangle_length(theta2, k.boom_o, k.boom_offset, k.boom_aa_bb, k.boom_two_ab)
    d3 = _triangle_length(theta3, k.arm_o, k.arm_offset, k.arm_aa_bb, k.arm_two_ab)
    cp, sp = cos_sin(theta4 + k.h_phase)
    hx, hy = k.h_radius * cp, k.h_radius * sp  # H - bucket pin
    tx, ty = k.pin_from_pivot_x + hx, k.pin_from_pivot_y + hy  # H - pivot
    ff = tx * tx + ty * ty
    f = np.sqrt(ff)
    c = (ff + k.side_hh) / (k.two_side * f)
    with np.errstate(invalid="ignore"):  # |c| > 1: the links cannot meet, NaN marks it
        s = np.sqrt(1.0 - c * c)
    u = k.side / f
    uc, us = u * c, u * s
    d4 = np.full_like(f, np.nan)
    for turn in (-1.0, 1.0):  # where both close on the assembly, the one inside the stroke wins
        rx, ry = uc * tx - turn * us * ty, uc * ty + turn * us * tx  # R - pivot
        side = k.base_from_pivot_x * ry - k.base_from_pivot_y * rx
        ex, ey = rx - k.pin_from_pivot_x, ry - k.pin_from_pivot_y  # R - bucket pin
        four_bar = ex * hy - ey * hx
        bx, by = rx - k.base_from_pivot_x, ry - k.base_from_pivot_y
        length = np.sqrt(bx * bx + by * by)
        in_stroke = (length >= k.stroke_lo) & (length <= k.stroke_hi)
        keep = (side * k.side_o > 0.0) & (four_bar * k.h_o > 0.0) & (np.isnan(d4) | in_stroke)
        d4 = np.where(keep, length, d4)
    return d2, d3, d4


def open_chain_candidates(
    model: Excavator, Q: np.ndarray, heading: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Every open-chain theta = [theta1..theta4] with eq. 3's Q(theta) = Q (..., 4), steps 1-3 of
    the module docstring: (theta (..., 4, 4) in BRANCHES order, NaN where the bucket pin is out
    of the arm's reach; reach (..., 4) of :class:`manipulator_kinematics.planar.Reach`).

    ``heading`` (...,): the swing of the first two candidates (a 6-D target's boom plane); the tip
    then lies at the signed radius x cos + y sin of it. Default atan2(y, x), the tip in front.
    """
    flat = Q.reshape(-1, 4)
    x, y, z, alpha = (flat[:, i : i + 1] for i in range(4))
    heading = np.arctan2(y, x) if heading is None else np.reshape(heading, (-1, 1))
    theta2, theta3, theta4, reach = open_chain_columns(model.ik_constants, x, y, z, alpha, heading)
    theta = np.stack((_swings(heading, theta2.shape), theta2, theta3, theta4), axis=-1)
    return theta.reshape(Q.shape[:-1] + (4, 4)), reach.reshape(Q.shape[:-1] + (4,))


def _swings(heading: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """theta1 (N, 4) of the candidates: the heading, then the heading + pi (wrapped)."""
    swing = np.empty(shape)
    swing[:, :2] = heading
    swing[:, 2:] = wrap_angle(heading + np.pi)
    return swing


def _block_candidates(
    model: Excavator, Q: np.ndarray, alpha: np.ndarray, heading: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """D (N, 4, 4), reach (N, 4) and status (N, 4) of flat targets Q (N, >= 3) at bucket angles
    alpha (N, 1) or (N, 4) (one per candidate); heading (N, 1) or None."""
    k = model.ik_constants
    x, y, z = Q[:, 0:1], Q[:, 1:2], Q[:, 2:3]
    if heading is None:
        heading = np.arctan2(y, x)
    with np.errstate(invalid="ignore"):
        theta2, theta3, theta4, reach = open_chain_columns(k, x, y, z, alpha, heading)
        d2, d3, d4 = linkage_length_columns(k, theta2, theta3, theta4)
    D = np.stack((_swings(heading, theta2.shape), d2, d3, d4), axis=-1)
    return D, reach, status(model, D, Q)


def candidates(model: Excavator, Q: np.ndarray, heading: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """Every D reaching Q = [x, y, z, alpha] (..., 4): (D (..., 4, 4), reach (..., 4), status
    (..., 4)), the open-chain candidates turned into cylinder lengths; NaN where there is no
    solution."""
    flat = Q.reshape(-1, 4)
    headings = None if heading is None else np.reshape(heading, (-1, 1))
    D, reach, judged = in_blocks(
        lambda Q, heading: _block_candidates(model, Q, Q[:, 3:4], heading), flat, headings
    )
    shape = Q.shape[:-1] + (4,)
    return D.reshape(shape + (4,)), reach.reshape(shape), judged.reshape(shape)


def status(model: Excavator, D: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """(N, 4) IKStatus of candidates D (N, 4, 4) of flat targets Q (N, >= 3) (module docstring):
    the shared limit_status, SINGULAR on the swing axis, INVALID for a target that is not finite."""
    judged = limit_status(D, model.joint_limits, LIMIT_TOL)
    on_axis = np.hypot(Q[:, 0], Q[:, 1]) <= SWING_AXIS
    judged[on_axis[:, None] & (judged == _SUCCESS)] = _SINGULAR
    judged[~np.isfinite(Q).all(axis=-1)] = _INVALID
    return judged


def _branch_index(branch: str | None) -> int | None:
    if branch is None:
        return None
    if branch not in BRANCHES:
        raise RequestError(
            f"unknown branch {branch!r}; known: {', '.join(BRANCHES)} (empty = closest to the seed)"
        )
    return BRANCHES.index(branch)


def _solutions(
    model: Excavator,
    Q: np.ndarray,
    D: np.ndarray,
    reach: np.ndarray,
    judged: np.ndarray,
    seed: np.ndarray | None,
    branch: int | None,
    other_heading: bool = False,
    selection: tuple[np.ndarray, np.ndarray] | None = None,
) -> IKSolutions:
    """IKSolutions of candidates D (..., 4, 4) of targets Q (..., 4, 4) (one per candidate) or
    (..., 1, 4) (one for every candidate) with statuses ``judged``; ``other_heading``: the last
    two candidates are refused for facing the other way (a 6-D target); ``selection``: (selected,
    tie) when already made (the kernel)."""
    if selection is None:
        selection = select(D, judged, seed=seed, branch=branch, weights=model.ik_constants.weights)
    selected, tie = selection

    def explain(solutions: IKSolutions, index: tuple[int, ...]) -> str:
        chosen = int(solutions.selected[index])
        if chosen >= 0:
            rule = (
                "the requested branch"
                if branch is not None
                else "closest to the seed"
                if seed is not None
                else "first valid in branch order"
            )
            tie = " (tie: another valid solution is as close to the seed)" if solutions.tie[index] else ""
            return f"branch {BRANCHES[chosen]} ({rule}){tie}"
        parts = []
        for i, name in enumerate(BRANCHES):
            if branch is not None and i != branch:
                continue
            if other_heading and i >= 2:
                note = "the swing of the other heading turns the bucket frame half a turn from the target's"
            else:
                note = _candidate_note(
                    model,
                    Q[index][min(i, len(Q[index]) - 1)],
                    D[index][i],
                    int(reach[index][i]),
                    int(judged[index][i]),
                )
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
    return (
        f"{distance:.6g} m from the boom foot pin, the arm reaches "
        f"[{abs(model.l2 - model.l3):.6g}, {model.l2 + model.l3:.6g}] m"
    )


def _seed(seed: ArrayLike | None, model: Excavator) -> np.ndarray | None:
    """The seed as floats, a continuous swing's angle wrapped into the candidates' (-pi, pi]."""
    if seed is None:
        return None
    seed = np.asarray(seed, dtype=float)
    if model.limits.continuous_swing and seed.shape[-1:] == (4,):
        seed = seed.copy()
        seed[..., 0] = wrap_swing(seed[..., 0])
    return seed


def _warm(ik_kernel: ModuleType, packed: np.ndarray) -> None:
    """Run each kernel function once (numba loads or compiles it); a kernel compiled for another
    layout is refused (layouts.check_compiled)."""
    check_compiled(ik_kernel)
    D, reach, judged = np.empty((4, 4)), np.empty(4, dtype=np.int8), np.empty(4, dtype=np.int8)
    alpha = np.zeros(4)
    ik_kernel.candidates(packed, 5.0, 0.0, 0.0, alpha, 0.0, D, reach)
    ik_kernel.judge(packed, 5.0, 0.0, True, SWING_AXIS, D, judged)
    ik_kernel.pick(packed, D, judged, alpha, False, -1, TIE_TOLERANCE)
    ik_kernel.widest_margin_angles(packed, 5.0, 0.0, 0.0, _GRID, _PEAKS, _GOLDEN, _GOLDEN_STEPS)
    selected, tie = np.empty(1, dtype=np.intp), np.empty(1, dtype=bool)
    ik_kernel.solve_batch(
        packed,
        alpha[None],
        _NO_SEEDS,
        False,
        -1,
        SWING_AXIS,
        TIE_TOLERANCE,
        D[None],
        reach[None],
        judged[None],
        selected,
        tie,
    )
    # The batch takes only these types: another (a read-only view, say) raises TypeError and the
    # call takes the numpy path, instead of compiling for seconds inside the call.
    ik_kernel.solve_batch.disable_compile()


#: The single-target kernel (:mod:`excavator_kinematics.core.ik_kernel`), see manipulator_kinematics.compiled.
KERNEL = Kernel("excavator_kinematics.core.ik_kernel", _warm)


def compiled_kernel(model: Excavator, wait: bool = False) -> ModuleType | None:
    """The compiled kernel module if ready, else None (:class:`manipulator_kinematics.compiled.Kernel`:
    the first single-target call starts loading it, calls take the numpy path meanwhile, the same
    results within 1e-12). ``wait``: load it now (tests, benchmarks)."""
    return KERNEL.get(model.ik_constants.packed, wait=wait)


def _solve_one(
    kernel,
    model: Excavator,
    position: np.ndarray,
    alpha: np.ndarray,
    finite: bool,
    seed: np.ndarray | None,
    branch: int | None,
) -> IKSolutions:
    """One target through the kernel: tip ``position`` (3,), candidate b at bucket angle alpha[b]."""
    k = model.ik_constants.packed
    x, y, z = position.tolist()
    D, reach, judged = np.empty((4, 4)), np.empty(4, dtype=np.int8), np.empty(4, dtype=np.int8)
    kernel.candidates(k, x, y, z, alpha, math.atan2(y, x), D, reach)
    kernel.judge(k, x, y, finite, SWING_AXIS, D, judged)
    seeded = seed is not None
    selected, tie = kernel.pick(
        k, D, judged, seed if seeded else alpha, seeded, -1 if branch is None else branch, TIE_TOLERANCE
    )
    Q = np.empty((4, 4))
    Q[:, :3], Q[:, 3] = position, alpha
    return _solutions(model, Q, D, reach, judged, seed, branch, selection=(np.array(selected), np.array(tie)))


def solve_pose(
    model: Excavator,
    Q: ArrayLike,
    seed: ArrayLike | None = None,
    branch: str | None = None,
    compiled: bool = True,
) -> IKSolutions:
    """Every candidate for targets Q = [x, y, z, alpha] (..., 4) and the selected one; one target
    (4,) and a batch (N, 4) run the compiled kernel (:func:`compiled_kernel`) unless not
    ``compiled``."""
    index = _branch_index(branch)
    Q = np.asarray(Q, dtype=float)
    if Q.shape[-1:] != (4,):
        raise ValueError(f"expected Q = [x, y, z, alpha] of shape (..., 4), got shape {Q.shape}")
    kernel = compiled_kernel(model) if compiled and Q.ndim <= 2 else None
    if kernel is not None and Q.ndim == 1:
        return _solve_one(
            kernel, model, Q[:3], np.full(4, Q[3]), bool(np.isfinite(Q).all()), _seed(seed, model), index
        )
    seed = _seed(seed, model)
    if kernel is not None and (seed is None or seed.shape in ((4,), Q.shape)):
        # A batch (N, 4) through the kernel's loop: the numpy path's fixed cost made a batch of
        # one 20x a single call and a batch paid from about 30 targets on (issue #32).
        n = len(Q)
        D, reach, judged = (
            np.empty((n, 4, 4)),
            np.empty((n, 4), dtype=np.int8),
            np.empty((n, 4), dtype=np.int8),
        )
        selected, tie = np.empty(n, dtype=np.intp), np.empty(n, dtype=bool)
        try:
            kernel.solve_batch(
                model.ik_constants.packed,
                np.ascontiguousarray(Q),
                _NO_SEEDS if seed is None else np.ascontiguousarray(seed.reshape(-1, 4)),
                seed is not None,
                -1 if index is None else index,
                SWING_AXIS,
                TIE_TOLERANCE,
                D,
                reach,
                judged,
                selected,
                tie,
            )
        except TypeError:  # arguments of types the loop does not take (_warm)
            pass
        else:
            return _solutions(model, Q[:, None], D, reach, judged, seed, index, selection=(selected, tie))
    D, reach, judged = candidates(model, Q)
    return _solutions(model, Q[..., None, :], D, reach, judged, seed, index)


def seed_bucket_angle(model: Excavator, seed: ArrayLike) -> np.ndarray:
    """alpha of the seed's pose, the seed first moved into the limits (it is a hint, not a state)."""
    seed = model.joint_limits.clip(np.asarray(seed, dtype=float))
    return model.pose(seed.reshape(-1, 4))[:, 3].reshape(seed.shape[:-1])


def stroke_margins(model: Excavator, D: np.ndarray) -> np.ndarray:
    """(...) min over the three cylinders of the distance to the nearer stroke end as a fraction
    of the stroke, of candidates D (..., 4); -inf where a candidate has no solution (NaN)."""
    k = model.ik_constants
    lengths = D[..., 1:]
    margin = np.minimum(lengths - k.stroke_min, k.stroke_max - lengths) / k.stroke_range
    margin = np.min(margin, axis=-1)
    return np.where(np.isnan(margin), -np.inf, margin)


def widest_margin_angles(model: Excavator, position: np.ndarray) -> np.ndarray:
    """(N, 4) per branch the bucket angle with the largest stroke margin at flat positions (N, 3)
    (module docstring). A branch without a solution at any grid angle gets -pi.

    The margin along alpha is piecewise smooth, its maxima where a margin peaks, where two
    margins are equal or where a linkage stops closing, and it has several: a grid of ``_GRID``
    angles over the full turn brackets them; each of the ``_PEAKS`` best local maxima of the grid
    is refined by ``_GOLDEN_STEPS`` golden-section steps over +- one grid step about it; the best
    refined one wins.
    """
    n = len(position)
    grid = np.linspace(-np.pi, np.pi, _GRID, endpoint=False)
    D, _, _ = _block_candidates(model, np.repeat(position, _GRID, axis=0), np.tile(grid, n)[:, None], None)
    margin = stroke_margins(model, D).reshape(n, _GRID, 4)
    found = np.isfinite(margin).any(axis=1)
    peak = (margin >= np.roll(margin, 1, axis=1)) & (margin >= np.roll(margin, -1, axis=1))
    # (N, peak, branch): the best peaks first, ties in grid order
    ranked = np.argsort(np.where(peak, -margin, np.inf), axis=1, kind="stable")[:, :_PEAKS]
    best = grid[ranked]
    value = np.take_along_axis(margin, ranked, axis=1)
    step = grid[1] - grid[0]
    at = np.repeat(position, _PEAKS, axis=0)

    def margins(alpha: np.ndarray) -> np.ndarray:  # (N, peak, branch): candidate b at alpha[..., b]
        D, _, _ = _block_candidates(model, at, alpha.reshape(-1, 4), None)
        return stroke_margins(model, D).reshape(alpha.shape)

    # Golden-section search for the maximum on [peak - step, peak + step], every peak and branch
    # at once: each step keeps the part with the better inner point and evaluates one new point.
    low, high = best - step, best + step
    inner_low, inner_high = high - _GOLDEN * (high - low), low + _GOLDEN * (high - low)
    value_low, value_high = margins(inner_low), margins(inner_high)
    for _ in range(_GOLDEN_STEPS):
        left = value_low >= value_high  # the maximum is in [low, inner_high], else in [inner_low, high]
        low, high = np.where(left, low, inner_low), np.where(left, inner_high, high)
        kept, kept_value = np.where(left, inner_low, inner_high), np.where(left, value_low, value_high)
        new = np.where(left, high - _GOLDEN * (high - low), low + _GOLDEN * (high - low))
        value_new = margins(new)
        inner_low, value_low = np.where(left, new, kept), np.where(left, value_new, kept_value)
        inner_high, value_high = np.where(left, kept, new), np.where(left, kept_value, value_new)
    left = value_low >= value_high
    refined, refined_value = np.where(left, inner_low, inner_high), np.where(left, value_low, value_high)
    better = refined_value > value  # never worse than the grid point
    best, value = np.where(better, refined, best), np.where(better, refined_value, value)
    winner = np.argmax(value, axis=1)[:, None, :]  # (N, 1, branch)
    return np.where(found, np.take_along_axis(best, winner, axis=1)[:, 0, :], -np.pi)


def solve_position(
    model: Excavator,
    position: ArrayLike,
    seed: ArrayLike | None = None,
    branch: str | None = None,
    compiled: bool = True,
) -> IKSolutions:
    """Every candidate for tip positions (..., 3), the bucket angle free (module docstring); one
    position (3,) runs the compiled kernel unless not ``compiled``."""
    index = _branch_index(branch)
    position = np.asarray(position, dtype=float)
    if position.shape[-1:] != (3,):
        raise ValueError(f"expected a position [x, y, z] of shape (..., 3), got shape {position.shape}")
    flat = position.reshape(-1, 3)
    seed = _seed(seed, model)
    kernel = compiled_kernel(model) if position.shape == (3,) and compiled else None
    if seed is not None:
        alpha = np.broadcast_to(seed_bucket_angle(model, seed), position.shape[:-1]).reshape(-1, 1)
        if kernel is not None:
            return _solve_one(
                kernel,
                model,
                position,
                np.full(4, alpha[0, 0]),
                bool(np.isfinite(position).all()),
                seed,
                index,
            )
    elif kernel is not None:
        finite = bool(np.isfinite(position).all())
        x, y, z = position.tolist() if finite else (0.0, 0.0, 0.0)
        alpha = kernel.widest_margin_angles(
            model.ik_constants.packed, x, y, z, _GRID, _PEAKS, _GOLDEN, _GOLDEN_STEPS
        )
        return _solve_one(kernel, model, position, alpha, finite, seed, index)
    else:
        finite = np.isfinite(flat).all(axis=-1, keepdims=True)
        usable = np.where(finite, flat, 0.0)
        # The search evaluates _GRID candidates per position: fewer positions per block.
        alpha = in_blocks(lambda p: widest_margin_angles(model, p), usable, block=max(BLOCK // _GRID, 1))
    D, reach, judged = in_blocks(lambda P, a: _block_candidates(model, P, a, None), flat, alpha)
    shape = position.shape[:-1] + (4,)
    alpha = np.broadcast_to(alpha, (len(flat), 4))
    Q = np.concatenate((np.broadcast_to(flat[:, None, :], (len(flat), 4, 3)), alpha[..., None]), axis=-1)
    return _solutions(
        model,
        Q.reshape(shape + (4,)),
        D.reshape(shape + (4,)),
        reach.reshape(shape),
        judged.reshape(shape),
        seed,
        index,
    )


def solve_ik(
    model: Excavator,
    target: ArrayLike,
    *,
    use_orientation: bool = True,
    mode: str | None = None,
    seed: ArrayLike | None = None,
    branch: str | None = None,
) -> IKSolutions:
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
        raise RequestError(
            "mode 'pose' takes the bucket angle from the target orientation: set use_orientation",
            IKStatus.INVALID,
        )
    if mode == "position" and use_orientation:
        raise RequestError(
            "mode 'position' leaves the bucket angle free: use mode 'pose' to give an orientation",
            IKStatus.INVALID,
        )
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
    D, reach, judged = candidates(model, Q, heading)
    judged[..., 2:] = _UNREACHABLE  # the other heading: not this orientation
    judged[rolled | off_plane] = _UNREACHABLE
    judged[~finite] = _INVALID
    solutions = _solutions(
        model,
        Q[..., None, :],
        D,
        reach,
        judged,
        _seed(seed, model),
        index,
        other_heading=True,
    )

    def explain(result: IKSolutions, where: tuple[int, ...]) -> str:
        if not finite[where]:
            return "target is not finite"
        if rolled[where]:
            roll = math.degrees(math.asin(min(1.0, abs(float(R[where][2, 1])))))
            return (
                f"target orientation rolls the bucket by {roll:.6g} deg: its y axis (the boom-plane "
                "normal) must be level"
            )
        if off_plane[where]:
            return (
                f"target position is {float(lateral[where]):.6g} m off the boom plane of the "
                f"orientation's heading {math.degrees(float(heading[where])):.6g} deg"
            )
        assert solutions.explain is not None  # _solutions always gives one
        return solutions.explain(result, where)

    return IKSolutions(
        q=D, status=judged, branches=BRANCHES, selected=solutions.selected, tie=solutions.tie, explain=explain
    )
