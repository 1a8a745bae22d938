"""The excavator's bag analysis (its ``analyse`` hook for ``evaluate``): the recorded outputs of
its nodes against the kinematics recomputed from the recorded inputs, the tracking of commanded
bucket twists, and cylinder and swing speed and stroke statistics.

The recomputation is what the forward node should have published for the recorded inputs:

* the swing state is the ``joint_states`` message with the cylinder message's stamp, or else the
  latest earlier one extrapolated with its rate (the node's first-order hold), within the forward
  node's ``swing_max_age``;
* accelerations are raw finite differences of successive rates (the node with
  ``acceleration_time_constant`` 0, its default), restarted after a gap over
  ``acceleration_max_gap``;
* ``urdf_joint_states`` (every URDF joint and its rate) and, when the node's ``grade`` is
  enabled, ``grade_height`` (the tip's height above the design plane) from the same state
  (:mod:`excavator_kinematics.nodes.display_outputs`);
* ``bucket_pose_level`` (the tip in the gravity-aligned level frame) from the latest
  ``machine_tilt`` at or before the cylinder stamp (:func:`excavator_kinematics.sensing.imu.level_rotation`).

With ``zone_clearance`` recorded, each avoidance zone's smallest clearance and its transgressions
(:func:`manipulator_kinematics.bag.zones.zone_report`).

The node settings come from the evaluation context (the package's config/excavator_nodes.yaml,
overridden by ``evaluate --params`` files).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from excavator_kinematics.core.kinematics import (
    CYLINDERS,
    JOINTS,
    STROKE_TOLERANCE,
    Excavator,
    bucket_angular_acceleration,
    bucket_angular_velocity,
    bucket_quaternion,
)
from excavator_kinematics.core.urdf_joints import URDF_JOINTS
from excavator_kinematics.grade.design_surface import SitePose, cutting_edge, read_landxml
from excavator_kinematics.nodes.display_outputs import DesignPlane, urdf_joint_states
from excavator_kinematics.sensing.imu import base_up, level_rotation
from manipulator_kinematics.bag.analysis import (
    AnalysisContext,
    Panel,
    Plot,
    consistency_plot,
    error_stats,
    finite_differences,
    match_exact,
    match_latest,
    quaternion_angle,
    since,
    vectors,
    wrap,
)
from manipulator_kinematics.bag.reader import TopicArrays
from manipulator_kinematics.bag.zones import zone_report

SWING = JOINTS[0]
# Outputs the forward node publishes for every accepted input.
EVERY_INPUT = ("bucket_pose", "bucket_twist", "open_chain_joint_states", "grade_height")
# Share of the stroke at either end that counts as "near the end".
NEAR_END = 0.01
# A command at or above this share of the speed limit counts as saturated.
SATURATED = 0.999


@dataclass(frozen=True)
class _Settings:
    """The node settings the recomputation mirrors."""

    swing_max_age: float
    acceleration_max_gap: float
    acceleration_time_constant: float
    command_timeout: float
    urdf_joint_states_rate: float
    grade: DesignPlane | None

    @classmethod
    def of(cls, context: AnalysisContext) -> _Settings:
        forward = context.node_settings["excavator_forward"]
        ik = context.node_settings["excavator_velocity_ik"]
        grade = forward.get("grade", {})
        return cls(
            float(forward["swing_max_age"]),
            float(forward["acceleration_max_gap"]),
            float(forward["acceleration_time_constant"]),
            float(ik["command_timeout"]),
            float(forward["urdf_joint_states_rate"]),
            DesignPlane.from_settings(grade) if grade.get("enabled") else None,
        )

    def used(self) -> dict[str, Any]:
        """The settings the recomputation mirrors, by their parameter names (for the report)."""
        return {
            "excavator_forward.swing_max_age": self.swing_max_age,
            "excavator_forward.acceleration_max_gap": self.acceleration_max_gap,
            "excavator_forward.acceleration_time_constant": self.acceleration_time_constant,
            "excavator_forward.urdf_joint_states_rate": self.urdf_joint_states_rate,
            "excavator_forward.grade.enabled": self.grade is not None,
            "excavator_velocity_ik.command_timeout": self.command_timeout,
        }


@dataclass
class _ExcavatorInputs:
    """Accepted inputs in stamp order and the state recomputed for them."""

    stamp: np.ndarray
    D: np.ndarray
    D_dot: np.ndarray
    known_ddot: np.ndarray
    theta1: np.ndarray
    state: Any
    recorded: int


def _inputs(
    cylinders: TopicArrays, joints: TopicArrays, exc: Excavator, m: _Settings
) -> _ExcavatorInputs | None:
    stamp = cylinders.stamp_ns()
    lengths = cylinders.by_name("position", CYLINDERS)
    rates = cylinders.by_name("velocity", CYLINDERS)
    swing_angle = joints.by_name("position", [SWING])[:, 0]
    swing_rows = np.isfinite(swing_angle)
    if not swing_rows.any():
        return None
    s_j = joints.stamp_ns()[swing_rows]
    angle, rate = swing_angle[swing_rows], joints.by_name("velocity", [SWING])[swing_rows, 0]
    # Swing accelerations as the node's differentiator sees them: over joint_states in stamp order.
    order = np.argsort(s_j, kind="stable")
    swing_ddot = np.empty_like(rate)
    swing_ddot[order] = finite_differences(s_j[order], rate[order, None], m.acceleration_max_gap)[:, 0]

    j = match_exact(stamp, s_j)
    j = np.where(j >= 0, j, match_latest(stamp, s_j))
    gap = np.where(j >= 0, (stamp - s_j[j]) * 1e-9, np.inf)
    theta1 = angle[j] + rate[j] * gap
    # Sensor readings -> true states, as the node's boundary does (Excavator.true_state).
    D = np.column_stack([theta1, lengths]) + exc.zero_offset
    D_dot = np.column_stack([rate[j], rates])
    lim = exc.limits
    accepted = (
        (j >= 0)
        & (np.abs(gap) <= m.swing_max_age)
        & np.all(np.isfinite(D), axis=1)
        & np.all(np.isfinite(D_dot), axis=1)
        & np.all(lim.d_min - STROKE_TOLERANCE <= D, axis=1)
        & np.all(lim.d_max + STROKE_TOLERANCE >= D, axis=1)
    )
    rows = np.flatnonzero(accepted)
    rows = rows[np.argsort(stamp[rows], kind="stable")]
    if not len(rows):
        return None
    D, D_dot, stamp, j = D[rows], D_dot[rows], stamp[rows], j[rows]
    # Only accepted cylinder messages feed the node's differencing.
    cylinder_ddot = finite_differences(stamp, D_dot[:, 1:], m.acceleration_max_gap)
    D_ddot = np.column_stack([swing_ddot[j], cylinder_ddot])
    known = np.all(np.isfinite(D_ddot), axis=1)
    state = exc.state(D, D_dot, np.where(known[:, None], D_ddot, 0.0))
    return _ExcavatorInputs(stamp, D, D_dot, known, D[:, 0], state, len(cylinders))


def _consistency(
    data: dict[str, TopicArrays],
    exc: Excavator,
    inputs: _ExcavatorInputs,
    m: _Settings,
    t0: int,
    plots: list[Plot],
    prefix: str,
    answered: dict[str, Any],
) -> dict[str, Any]:
    """The errors of the outputs against the recomputation; in ``answered`` the counts of inputs
    and outputs per output topic (:func:`_answered`)."""
    s = inputs.state
    out: dict[str, Any] = {}
    curves: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    # Which accepted inputs the node answers on each output (the rest it skips by its settings).
    expected = {topic: np.ones(len(inputs.stamp), bool) for topic in EVERY_INPUT}
    expected["bucket_accel"] = inputs.known_ddot
    expected["urdf_joint_states"] = _urdf_due(inputs.stamp, m.urdf_joint_states_rate)

    def matched(topic: str) -> tuple[TopicArrays, np.ndarray, np.ndarray, dict[str, Any]] | None:
        if topic not in data:
            return None
        arrays = data[topic]
        k = match_exact(arrays.stamp_ns(), inputs.stamp)
        rows = np.flatnonzero(k >= 0)
        entry = {"matched": int(rows.size), "unmatched": int(len(k) - rows.size)}
        if topic in expected:
            answered[topic] = _answered(inputs, expected[topic], k[rows])
        out[topic] = entry
        return arrays, rows, k[rows], entry

    if found := matched("bucket_pose"):
        arrays, rows, k, entry = found
        position = np.linalg.norm(vectors(arrays, "pose.position")[rows] - s.Q[k, :3], axis=1)
        quaternion = np.stack([arrays[f"pose.orientation.{a}"] for a in "xyzw"], axis=-1)[rows]
        rotation = quaternion_angle(quaternion, bucket_quaternion(inputs.theta1[k], s.Q[k, 3]))
        entry.update(position_m=error_stats(position), orientation_rad=error_stats(rotation))
        curves["bucket_pose position (m)"] = (since(arrays.stamp_ns()[rows], t0), position)
    if found := matched("bucket_twist"):
        arrays, rows, k, entry = found
        linear = np.linalg.norm(vectors(arrays, "twist.linear")[rows] - s.Q_dot[k, :3], axis=1)
        omega = bucket_angular_velocity(inputs.theta1[k], inputs.D_dot[k, 0], s.Q_dot[k, 3])
        angular = np.linalg.norm(vectors(arrays, "twist.angular")[rows] - omega, axis=1)
        entry.update(linear_mps=error_stats(linear), angular_radps=error_stats(angular))
        curves["bucket_twist linear (m/s)"] = (since(arrays.stamp_ns()[rows], t0), linear)
    if (found := matched("bucket_accel")) and m.acceleration_time_constant > 0:
        found[3]["not_compared"] = (
            f"the node low-pass filters accelerations (acceleration_time_constant "
            f"{m.acceleration_time_constant:g} s); the recomputation uses raw differences"
        )
    elif found:
        arrays, rows, k, entry = found
        known = inputs.known_ddot[k]
        rows, k = rows[known], k[known]
        entry["without_recomputed_acceleration"] = int(np.sum(~known))
        linear = np.linalg.norm(vectors(arrays, "accel.linear")[rows] - s.Q_ddot[k, :3], axis=1)
        alpha = bucket_angular_acceleration(
            inputs.theta1[k], inputs.D_dot[k, 0], s.theta_ddot[k, 0], s.Q_dot[k, 3], s.Q_ddot[k, 3]
        )
        angular = np.linalg.norm(vectors(arrays, "accel.angular")[rows] - alpha, axis=1)
        entry.update(linear_mps2=error_stats(linear), angular_radps2=error_stats(angular))
        curves["bucket_accel linear (m/s²)"] = (since(arrays.stamp_ns()[rows], t0), linear)
    if found := matched("open_chain_joint_states"):
        arrays, rows, k, entry = found
        angles = np.abs(wrap(arrays.by_name("position", JOINTS)[rows] - s.theta[k])).max(axis=1)
        rates = np.abs(arrays.by_name("velocity", JOINTS)[rows] - s.theta_dot[k]).max(axis=1)
        entry.update(angle_rad=error_stats(angles), rate_radps=error_stats(rates))
        curves["open_chain_joint_states angle (rad)"] = (since(arrays.stamp_ns()[rows], t0), angles)
    if found := matched("urdf_joint_states"):
        arrays, rows, k, entry = found
        positions, rates = urdf_joint_states(exc, inputs.D[k], inputs.D_dot[k])
        angles = np.abs(wrap(arrays.by_name("position", URDF_JOINTS)[rows] - positions)).max(axis=1)
        speeds = np.abs(arrays.by_name("velocity", URDF_JOINTS)[rows] - rates).max(axis=1)
        entry.update(position=error_stats(angles), rate=error_stats(speeds))
        curves["urdf_joint_states position (rad, m)"] = (since(arrays.stamp_ns()[rows], t0), angles)
    if (found := matched("grade_height")) and m.grade is not None:
        arrays, rows, k, entry = found
        height = np.abs(arrays["point.z"][rows] - m.grade.height(s.Q[k, :3]))
        entry.update(height_m=error_stats(height))
        curves["grade_height (m)"] = (since(arrays.stamp_ns()[rows], t0), height)
    if (found := matched("bucket_pose_level")) and "machine_tilt" in data:
        arrays, rows, k, entry = found
        tilt = data["machine_tilt"]
        t = match_latest(inputs.stamp[k], tilt.stamp_ns())
        rows, k, t = rows[t >= 0], k[t >= 0], t[t >= 0]
        rotation = level_rotation(base_up(vectors(tilt, "vector")[t], inputs.theta1[k]))
        tip = np.einsum("nij,nj->ni", rotation, s.Q[k, :3])
        position = np.linalg.norm(vectors(arrays, "pose.position")[rows] - tip, axis=1)
        entry.update(position_m=error_stats(position))
        curves["bucket_pose_level position (m)"] = (since(arrays.stamp_ns()[rows], t0), position)
    consistency_plot(plots, f"{prefix}consistency", curves)
    return out


def _urdf_due(stamp: np.ndarray, rate: float) -> np.ndarray:
    """The accepted inputs (stamp order) the forward node answers on ``urdf_joint_states``: at most
    ``rate`` per second of input stamps, as its rate limit decides (0 Hz: every one)."""
    period = int(1e9 / rate) if rate > 0 else 0
    due, last = np.zeros(len(stamp), bool), None
    for i, t in enumerate(stamp.tolist()):
        if last is None or not 0 <= t - last < period:
            due[i], last = True, t
    return due


def _answered(inputs: _ExcavatorInputs, expected: np.ndarray, k: np.ndarray) -> dict[str, Any]:
    """Inputs against the outputs of one topic: how many were recorded, accepted (by the node's
    settings: swing age, strokes, finite values), due an output (the node's rate limits), and due
    ones without an output. Only inputs between the first and the last answered one count as
    missing: the recorder subscribes to each topic when its publisher appears and stops all at
    once, so the edges say nothing about the node."""
    answered = np.zeros(len(inputs.stamp), bool)
    answered[k] = True
    hit = np.flatnonzero(answered)
    inside = np.zeros(len(answered), bool)
    if hit.size:
        inside[hit[0] : hit[-1] + 1] = True
    due = expected & inside
    return {
        "recorded": inputs.recorded,
        "accepted": len(answered),
        "due": int(due.sum()),
        "answered": int(hit.size),
        "missing": int(np.sum(due & ~answered)),
        "outside_recording": int(np.sum(expected & ~inside)),
    }


def _tracking(
    target: TopicArrays, achieved: TopicArrays, m: _Settings, t0: int, plots: list[Plot], prefix: str
) -> dict[str, Any]:
    s_t, s_b = target.stamp_ns(), achieved.stamp_ns()
    k = match_latest(s_b, s_t)
    active = (k >= 0) & ((s_b - s_t[k]) * 1e-9 <= m.command_timeout)
    rows, k = np.flatnonzero(active), k[active]
    commanded, reached = vectors(target, "twist.linear")[k], vectors(achieved, "twist.linear")[rows]
    linear = np.linalg.norm(reached - commanded, axis=1)
    angular = np.linalg.norm(
        vectors(achieved, "twist.angular")[rows] - vectors(target, "twist.angular")[k], axis=1
    )
    t = since(s_b[rows], t0)
    panels = [
        Panel(f"v{axis} (m/s)", {"commanded": (t, commanded[:, i]), "achieved": (t, reached[:, i])})
        for i, axis in enumerate("xyz")
    ]
    plots.append(Plot(f"{prefix}tracking", "Bucket twist: commanded vs achieved", panels))
    return {
        "matched": int(rows.size),
        "without_active_command": int(np.sum(~active)),
        "linear_mps": error_stats(linear),
        "angular_radps": error_stats(angular),
    }


def _actuators(
    data: dict[str, TopicArrays], exc: Excavator, t0: int, plots: list[Plot], prefix: str
) -> dict[str, Any]:
    lim = exc.limits
    out: dict[str, Any] = {}
    if "cylinder_lengths" in data:
        cyl = data["cylinder_lengths"]
        # True lengths (reading + zero_offset): the strokes are physical.
        lengths = cyl.by_name("position", CYLINDERS) + exc.zero_offset[1:]
        rates = cyl.by_name("velocity", CYLINDERS)
        t = since(cyl.stamp_ns(), t0)
        for i, name in enumerate(CYLINDERS):
            low, high, limit = lim.stroke_min[i], lim.stroke_max[i], lim.max_cylinder_speed[i]
            d, v = lengths[:, i], rates[:, i]
            have, d = np.isfinite(d), d[np.isfinite(d)]
            near = NEAR_END * (high - low)
            at_end = (d <= low + near) | (d >= high - near)
            speed = np.abs(v[np.isfinite(v)])
            # A cylinder whose values are all NaN keeps its row (with its NaN counts): a field that
            # is missing from the report would look like one that was never recorded.
            out[name] = {
                "samples": len(have),
                "non_finite_length": int(np.sum(~have)),
                "non_finite_speed": int(len(v) - speed.size),
                "length_min_m": float(d.min()) if d.size else None,
                "length_max_m": float(d.max()) if d.size else None,
                "stroke_used": float((d.max() - d.min()) / (high - low)) if d.size else None,
                "near_end_fraction": float(np.mean(at_end)) if d.size else None,
                "beyond_end": int(np.sum((d < low - STROKE_TOLERANCE) | (d > high + STROKE_TOLERANCE))),
                "speed_max_mps": float(speed.max()) if speed.size else None,
                "speed_limit_mps": float(limit),
                "over_speed": int(np.sum(speed > limit * (1 + 1e-9))),
            }
        plots.append(
            Plot(
                f"{prefix}cylinders",
                "Cylinder lengths and speeds with their limits",
                [
                    panel
                    for i, name in enumerate(CYLINDERS)
                    for panel in (
                        Panel(
                            f"{name} (m)",
                            {"length": (t, lengths[:, i])},
                            [float(lim.stroke_min[i]), float(lim.stroke_max[i])],
                        ),
                        Panel(
                            f"{name} (m/s)",
                            {"speed": (t, rates[:, i])},
                            [float(-lim.max_cylinder_speed[i]), float(lim.max_cylinder_speed[i])],
                        ),
                    )
                ],
            )
        )
    if "joint_states" in data:
        js = data["joint_states"]
        angle, rate = js.by_name("position", [SWING])[:, 0], js.by_name("velocity", [SWING])[:, 0]
        # A message without the swing joint reads as NaN too: counted with the non-finite ones.
        finite = angle[np.isfinite(angle)]
        speed = np.abs(rate[np.isfinite(rate)])
        out[SWING] = {
            "samples": len(angle),
            "non_finite_angle": int(len(angle) - finite.size),
            "non_finite_speed": int(len(rate) - speed.size),
            "angle_min_rad": float(finite.min()) if finite.size else None,
            "angle_max_rad": float(finite.max()) if finite.size else None,
            "speed_max_radps": float(speed.max()) if speed.size else None,
            "speed_limit_radps": float(lim.max_swing_speed),
            "over_speed": int(np.sum(speed > lim.max_swing_speed * (1 + 1e-9))),
        }
    if "cylinder_rate_commands" in data:
        commands = data["cylinder_rate_commands"].by_name("velocity", [*CYLINDERS, SWING])
        limits = np.concatenate([lim.max_cylinder_speed, [lim.max_swing_speed]])
        out["commands"] = {
            name: {
                "max": float(np.nanmax(np.abs(commands[:, i])))
                if np.isfinite(commands[:, i]).any()
                else None,
                "limit": float(limits[i]),
                "saturated_fraction": float(np.mean(np.abs(commands[:, i]) >= SATURATED * limits[i])),
            }
            for i, name in enumerate([*CYLINDERS, SWING])
        }
    return out


def analyse(
    data: dict[str, TopicArrays], exc: Excavator, context: AnalysisContext
) -> tuple[dict[str, Any], list[Plot]]:
    """The excavator's ``analyse`` hook: report of one excavator's topics (relative names ->
    arrays) and its plots (module docstring)."""
    m = _Settings.of(context)
    t0, prefix = context.t0, context.prefix
    report: dict[str, Any] = {"settings_used": m.used()}
    plots: list[Plot] = []
    if "cylinder_lengths" in data and "joint_states" in data:
        inputs = _inputs(data["cylinder_lengths"], data["joint_states"], exc, m)
        if inputs is not None:
            report["accepted_inputs"] = len(inputs.stamp)
            report["inputs_to_outputs"] = {}
            report["consistency"] = _consistency(
                data, exc, inputs, m, t0, plots, prefix, report["inputs_to_outputs"]
            )
    if "target_bucket_twist" in data and "bucket_twist" in data:
        target, achieved = data["target_bucket_twist"], data["bucket_twist"]
        report["tracking"] = _tracking(target, achieved, m, t0, plots, prefix)
    report["actuators"] = _actuators(data, exc, t0, plots, prefix)
    if "zone_clearance" in data:
        report["zones"] = zone_report(data["zone_clearance"], t0)
    return report, plots


#: Units of the per-sample table's columns (docs/asbuilt.md), by name or name prefix.
SAMPLE_UNITS = {
    "stamp_ns": "ns",
    "swing_joint": "rad",
    "swing_joint_rate": "rad/s",
    "alpha": "rad",
    "published": "bool",
    "grade_": "m (height above the design surface, + = cut)",
}


def samples(
    data: dict[str, TopicArrays], exc: Excavator, context: AnalysisContext
) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The excavator's ``samples`` hook: one row per input the forward node accepted (the same
    rule as :func:`analyse`), in stamp order: the actuators and their rates, the tip Q (eq. 3;
    base frame), both cutting-edge corners in the base and the site frame, the grade heights
    where a design surface or plane is set, and whether the node published a pose for it.
    Returns the columns and their units. No rows (empty columns) without both input topics."""
    m = _Settings.of(context)
    forward = context.node_settings["excavator_forward"]
    inputs = None
    if "cylinder_lengths" in data and "joint_states" in data:
        inputs = _inputs(data["cylinder_lengths"], data["joint_states"], exc, m)
    n = 0 if inputs is None else len(inputs.stamp)
    D = np.empty((0, 4)) if inputs is None else inputs.D
    D_dot = np.empty((0, 4)) if inputs is None else inputs.D_dot
    Q = np.empty((0, 4)) if inputs is None else inputs.state.Q
    edge = cutting_edge(Q[:, :3], D[:, 0], exc.bucket_width)  # (n, 3: tip, left, right, 3)
    stamp = np.empty(0, np.int64) if inputs is None else inputs.stamp
    site = _site_points(data, forward["design_surface"], stamp, edge)
    columns: dict[str, np.ndarray] = {"stamp_ns": stamp}
    units = dict(SAMPLE_UNITS)
    for j, name in enumerate((SWING, *CYLINDERS)):
        columns[name], columns[f"{name}_rate"] = D[:, j], D_dot[:, j]
        if j:
            units[name], units[f"{name}_rate"] = "m", "m/s"
    columns["alpha"] = Q[:, 3]
    for frame, points, unit in (("", edge, "m (base frame)"), ("_site", site, "m (site frame)")):
        for k, point in enumerate(("tip", "left", "right")):
            for j, axis in enumerate("xyz"):
                columns[f"{point}{frame}_{axis}"] = points[:, k, j]
                units[f"{point}{frame}_{axis}"] = unit
    surface = forward["design_surface"]
    if surface.get("file"):
        tin = read_landxml(surface["file"], surface["surface"])
        for k, point in enumerate(("tip", "left", "right")):
            columns[f"grade_{point}"] = tin.heights(site[:, k]).height
    elif m.grade is not None:
        columns["grade_tip"] = m.grade.height(Q[:, :3])
    poses = data.get("bucket_pose")
    columns["published"] = (
        np.zeros(n, bool) if poses is None or not n else match_exact(stamp, poses.stamp_ns()) >= 0
    )
    return columns, units


def _site_points(
    data: dict[str, TopicArrays], surface: dict[str, Any], stamp: np.ndarray, points: np.ndarray
) -> np.ndarray:
    """``points`` (n, k, 3) of the base frame in the site frame, as the forward node places the
    machine (``design_surface.site_pose_source``): a fixed pose, or the latest recorded
    ``site_pose`` at most ``site_pose_max_age`` old (NaN where there is none)."""
    if surface["site_pose_source"] != "topic":
        return SitePose.from_rpy(surface["site_position"], surface["site_rpy"]).apply(points)
    out = np.full(points.shape, np.nan)
    poses = data.get("site_pose")
    if poses is None or not len(poses) or not len(stamp):
        return out
    j = match_latest(stamp, poses.stamp_ns())
    age = np.where(j >= 0, (stamp - poses.stamp_ns()[j]) * 1e-9, np.inf)
    ok = age <= float(surface["site_pose_max_age"])
    if ok.any():
        position = vectors(poses, "pose.position")[j[ok]]
        quaternion = np.column_stack([poses[f"pose.orientation.{a}"] for a in "xyzw"])[j[ok]]
        pose = SitePose(Rotation.from_quat(quaternion).as_matrix(), position[:, None, :])
        out[ok] = pose.apply(points[ok])
    return out
