"""What ``evaluate`` computes from a bag: numpy over all messages at once, no rclpy.

For each topic: message rate, gaps and latency (record time minus header stamp). For each machine
found in the bag (an excavator or a SCARA arm per namespace): consistency of the published
outputs with the kinematics recomputed by the numpy core from the recorded inputs (matched by
header stamp, since the nodes stamp outputs with their input's stamp), and for the excavator the
tracking of the commanded bucket twist, cylinder speed and stroke statistics.

The recomputation is what the forward node should have published for the recorded inputs:

* the swing state is the ``joint_states`` message with the cylinder message's stamp, or else the
  latest earlier one extrapolated with its rate (the node's first-order hold), within
  ``swing_max_age`` of the node's config;
* accelerations are raw finite differences of successive rates (the node with
  ``acceleration_time_constant`` 0, its default), restarted after a gap over
  ``acceleration_max_gap``.

Errors are reported as max and RMS over matched messages.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from excavator_kinematics.kinematics import (
    CYLINDERS,
    JOINTS,
    STROKE_TOLERANCE,
    Excavator,
    bucket_angular_acceleration,
    bucket_angular_velocity,
    bucket_quaternion,
)
from manipulator_kinematics.bag.io import TopicArrays
from manipulator_kinematics.bag.topics import node_settings
from manipulator_kinematics.planar import yaw_quaternion
from scara_kinematics.kinematics import Scara

SWING = JOINTS[0]
# A gap longer than this many median periods counts as a gap in the topic statistics.
GAP_FACTOR = 2.5
# Share of the stroke at either end that counts as "near the end".
NEAR_END = 0.01
# A command at or above this share of the speed limit counts as saturated.
SATURATED = 0.999
EXCAVATOR_TOPICS = (
    "cylinder_lengths",
    "bucket_pose",
    "bucket_twist",
    "bucket_accel",
    "open_chain_joint_states",
    "target_bucket_twist",
    "cylinder_rate_commands",
)
SCARA_TOPICS = ("tool_pose", "tool_twist")


@dataclass
class Panel:
    """Curves over time (s) sharing a y axis, with horizontal limit lines."""

    ylabel: str
    curves: dict[str, tuple[np.ndarray, np.ndarray]]
    limits: list[float] = field(default_factory=list)
    log: bool = False


@dataclass
class Plot:
    """One figure: panels stacked over a shared time axis."""

    name: str
    title: str
    panels: list[Panel]


@dataclass
class Machines:
    """The numpy models to recompute with, and the node settings the recomputation mirrors."""

    excavator: Excavator
    scara: Scara
    swing_max_age: float
    acceleration_max_gap: float
    acceleration_time_constant: float
    command_timeout: float

    @classmethod
    def from_parameters(
        cls, params: Mapping[str, Any], nodes: Mapping[str, Mapping[str, Any]] | None = None
    ) -> Machines:
        """Machines from a merged ROS parameters dict (``excavator:``/``scara:`` sections), default
        machines for a missing section; node settings from the package's node config, overridden
        by ``nodes`` (node name -> its settings)."""
        nodes = nodes or {}
        forward = {**node_settings("excavator_forward"), **nodes.get("excavator_forward", {})}
        ik = {**node_settings("excavator_velocity_ik"), **nodes.get("excavator_velocity_ik", {})}
        return cls(
            Excavator.from_parameters(params["excavator"]) if "excavator" in params else Excavator.default(),
            Scara.from_parameters(params["scara"]) if "scara" in params else Scara.default(),
            float(forward["swing_max_age"]),
            float(forward["acceleration_max_gap"]),
            float(forward["acceleration_time_constant"]),
            float(ik["command_timeout"]),
        )


# ------------------------------------------------------------------------------------------ helpers


def error_stats(errors: np.ndarray) -> dict[str, float | int | None]:
    """max, RMS and count of the finite entries."""
    errors = np.asarray(errors, dtype=float)
    errors = errors[np.isfinite(errors)]
    if not errors.size:
        return {"max": None, "rms": None, "count": 0}
    return {
        "max": float(np.max(np.abs(errors))),
        "rms": float(np.sqrt(np.mean(errors**2))),
        "count": int(errors.size),
    }


def match_exact(query: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """For each query value the index of an equal reference value (the last one), -1 if none."""
    order = np.argsort(reference, kind="stable")
    ordered = reference[order]
    at = np.searchsorted(ordered, query, side="right") - 1
    safe = np.clip(at, 0, None)
    found = (at >= 0) & (ordered[safe] == query) if len(ordered) else np.zeros(len(query), bool)
    return np.where(found, order[safe] if len(ordered) else 0, -1)


def match_latest(query: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """For each query value the index of the largest reference value <= it, -1 if none."""
    order = np.argsort(reference, kind="stable")
    at = np.searchsorted(reference[order], query, side="right") - 1
    return np.where(at >= 0, order[np.clip(at, 0, None)] if len(order) else 0, -1)


def wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def quaternion_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation angle between unit quaternions [x, y, z, w] (..., 4), accurate for tiny angles."""
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    w = np.sum(a * b, axis=-1)
    vector = a[..., 3:] * b[..., :3] - b[..., 3:] * a[..., :3] - np.cross(a[..., :3], b[..., :3])
    return 2.0 * np.arctan2(np.linalg.norm(vector, axis=-1), np.abs(w))


def vectors(arrays: TopicArrays, prefix: str) -> np.ndarray:
    return np.stack([arrays[f"{prefix}.{axis}"] for axis in "xyz"], axis=-1).astype(float)


def finite_differences(t_ns: np.ndarray, values: np.ndarray, max_gap: float) -> np.ndarray:
    """(v_k - v_k-1) / (t_k - t_k-1) for rows in time order; NaN for the first row and after a gap
    that is not in (0, max_gap] (the node restarts its differencing there)."""
    out = np.full_like(values, np.nan)
    dt = np.diff(t_ns) * 1e-9
    ok = (dt > 0) & (dt <= max_gap * (1 + 1e-12))
    out[1:][ok] = (np.diff(values, axis=0)[ok]) / dt[ok, None]
    return out


def topic_stats(arrays: TopicArrays) -> dict[str, Any]:
    """Count, rate, gaps (record time) and latency (record time - header stamp) of one topic."""
    t = arrays.log_time
    out: dict[str, Any] = {"type": arrays.msgtype, "count": len(t)}
    if len(t) >= 2:
        period = np.diff(t) * 1e-9
        median = float(np.median(period))
        out.update(
            rate_hz=(len(t) - 1) / ((t[-1] - t[0]) * 1e-9) if t[-1] > t[0] else None,
            period_median_s=median,
            gap_max_s=float(period.max()),
            gaps=int(np.sum(period > GAP_FACTOR * median)) if median > 0 else 0,
        )
    if "header.stamp.sec" in arrays.fields and len(t):
        stamp = arrays.stamp_ns()
        latency = (t - stamp) * 1e-9
        out["latency_s"] = {
            "median": float(np.median(latency)),
            "p99": float(np.percentile(latency, 99)),
            "max": float(latency.max()),
            "min": float(latency.min()),
        }
        out["stamps_backwards"] = int(np.sum(np.diff(stamp) < 0))
    return out


def since(t_ns: np.ndarray, t0: int) -> np.ndarray:
    return (t_ns - t0) * 1e-9


# ------------------------------------------------------------------------------------------ excavator


@dataclass
class _ExcavatorInputs:
    """Accepted inputs in stamp order and the state recomputed for them."""

    stamp: np.ndarray
    D: np.ndarray
    D_dot: np.ndarray
    known_ddot: np.ndarray
    theta1: np.ndarray
    state: Any


def _excavator_inputs(cylinders: TopicArrays, joints: TopicArrays, m: Machines) -> _ExcavatorInputs | None:
    exc = m.excavator
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
    D = np.column_stack([theta1, lengths])
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
    return _ExcavatorInputs(stamp, D, D_dot, known, D[:, 0], state)


def _consistency_plot(plots: list[Plot], name: str, curves: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    """The |error| curves of a machine's outputs against the recomputed kinematics, if any."""
    if curves:
        panel = Panel("|error|", curves, log=True)
        plots.append(Plot(name, "Published outputs vs recomputed kinematics", [panel]))


def _excavator_consistency(
    data: dict[str, TopicArrays],
    inputs: _ExcavatorInputs,
    m: Machines,
    t0: int,
    plots: list[Plot],
    prefix: str,
) -> dict[str, Any]:
    s = inputs.state
    out: dict[str, Any] = {}
    curves: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def matched(topic: str) -> tuple[TopicArrays, np.ndarray, np.ndarray, dict[str, Any]] | None:
        if topic not in data:
            return None
        arrays = data[topic]
        k = match_exact(arrays.stamp_ns(), inputs.stamp)
        rows = np.flatnonzero(k >= 0)
        entry = {"matched": int(rows.size), "unmatched": int(len(k) - rows.size)}
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
    _consistency_plot(plots, f"{prefix}excavator_consistency", curves)
    return out


def _excavator_tracking(
    target: TopicArrays, achieved: TopicArrays, m: Machines, t0: int, plots: list[Plot], prefix: str
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
    plots.append(Plot(f"{prefix}excavator_tracking", "Bucket twist: commanded vs achieved", panels))
    return {
        "matched": int(rows.size),
        "without_active_command": int(np.sum(~active)),
        "linear_mps": error_stats(linear),
        "angular_radps": error_stats(angular),
    }


def _excavator_actuators(
    data: dict[str, TopicArrays], m: Machines, t0: int, plots: list[Plot], prefix: str
) -> dict[str, Any]:
    lim = m.excavator.limits
    out: dict[str, Any] = {}
    if "cylinder_lengths" in data:
        cyl = data["cylinder_lengths"]
        lengths, rates = cyl.by_name("position", CYLINDERS), cyl.by_name("velocity", CYLINDERS)
        t = since(cyl.stamp_ns(), t0)
        for i, name in enumerate(CYLINDERS):
            low, high, limit = lim.stroke_min[i], lim.stroke_max[i], lim.max_cylinder_speed[i]
            d, v = lengths[:, i], rates[:, i]
            have = np.isfinite(d)
            if not have.any():
                continue
            near = NEAR_END * (high - low)
            speed = np.abs(v[np.isfinite(v)])
            out[name] = {
                "length_min_m": float(d[have].min()),
                "length_max_m": float(d[have].max()),
                "stroke_used": float((d[have].max() - d[have].min()) / (high - low)),
                "near_end_fraction": float(np.mean((d[have] <= low + near) | (d[have] >= high - near))),
                "beyond_end": int(
                    np.sum((d[have] < low - STROKE_TOLERANCE) | (d[have] > high + STROKE_TOLERANCE))
                ),
                "speed_max_mps": float(speed.max()) if speed.size else None,
                "speed_limit_mps": float(limit),
                "over_speed": int(np.sum(speed > limit * (1 + 1e-9))),
            }
        plots.append(
            Plot(
                f"{prefix}excavator_cylinders",
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
        if np.isfinite(angle).any():
            speed = np.abs(rate[np.isfinite(rate)])
            out[SWING] = {
                "angle_min_rad": float(np.nanmin(angle)),
                "angle_max_rad": float(np.nanmax(angle)),
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


def excavator(
    data: dict[str, TopicArrays], m: Machines, t0: int, prefix: str
) -> tuple[dict[str, Any], list[Plot]]:
    """Report of one excavator's topics (relative names -> arrays) and its plots."""
    report: dict[str, Any] = {}
    plots: list[Plot] = []
    if "cylinder_lengths" in data and "joint_states" in data:
        inputs = _excavator_inputs(data["cylinder_lengths"], data["joint_states"], m)
        if inputs is not None:
            report["accepted_inputs"] = len(inputs.stamp)
            report["consistency"] = _excavator_consistency(data, inputs, m, t0, plots, prefix)
    if "target_bucket_twist" in data and "bucket_twist" in data:
        report["tracking"] = _excavator_tracking(
            data["target_bucket_twist"], data["bucket_twist"], m, t0, plots, prefix
        )
    report["actuators"] = _excavator_actuators(data, m, t0, plots, prefix)
    return report, plots


# ------------------------------------------------------------------------------------------ SCARA


def scara(
    data: dict[str, TopicArrays], m: Machines, t0: int, prefix: str
) -> tuple[dict[str, Any], list[Plot]]:
    """Report of one SCARA arm: tool_pose / tool_twist vs the forward kinematics of joint_states."""
    report: dict[str, Any] = {}
    plots: list[Plot] = []
    if "joint_states" not in data:
        return report, plots
    arm = m.scara
    js = data["joint_states"]
    q, qd = js.by_name("position", arm.joint_names), js.by_name("velocity", arm.joint_names)
    rows = np.flatnonzero(np.all(np.isfinite(q), axis=1))
    stamp = js.stamp_ns()[rows]
    q, qd = q[rows], qd[rows]
    report["joint_states"] = len(rows)
    report["outside_limits"] = int(np.sum(~arm.within_limits(q)))
    curves = {}
    if "tool_pose" in data:
        pose = data["tool_pose"]
        k = match_exact(pose.stamp_ns(), stamp)
        got = np.flatnonzero(k >= 0)
        k = k[got]
        x = arm.fk(q[k])
        expected = np.column_stack([x[:, :2], np.zeros(len(k))])
        position = np.linalg.norm(vectors(pose, "pose.position")[got] - expected, axis=1)
        quaternion = np.stack([pose[f"pose.orientation.{a}"] for a in "xyzw"], axis=-1)[got]
        rotation = quaternion_angle(quaternion, yaw_quaternion(x[:, 2]))
        report["tool_pose"] = {
            "matched": int(got.size),
            "unmatched": int(len(pose) - got.size),
            "position_m": error_stats(position),
            "orientation_rad": error_stats(rotation),
        }
        curves["tool_pose position (m)"] = (since(pose.stamp_ns()[got], t0), position)
    if "tool_twist" in data:
        twist = data["tool_twist"]
        k = match_exact(twist.stamp_ns(), stamp)
        got = np.flatnonzero(k >= 0)
        k = k[got]
        known = np.all(np.isfinite(qd[k]), axis=1)
        got, k = got[known], k[known]
        xd = arm.velocity_fk(q[k], qd[k])
        linear = np.linalg.norm(
            vectors(twist, "twist.linear")[got] - np.column_stack([xd[:, :2], np.zeros(len(k))]), axis=1
        )
        omega = np.column_stack([np.zeros((len(k), 2)), xd[:, 2]])
        angular = np.linalg.norm(vectors(twist, "twist.angular")[got] - omega, axis=1)
        report["tool_twist"] = {
            "matched": int(got.size),
            "unmatched": int(len(twist) - got.size),
            "linear_mps": error_stats(linear),
            "angular_radps": error_stats(angular),
        }
        curves["tool_twist linear (m/s)"] = (since(twist.stamp_ns()[got], t0), linear)
    _consistency_plot(plots, f"{prefix}scara_consistency", curves)
    return report, plots


def has_scara_joints(js: TopicArrays, m: Machines) -> bool:
    return bool(np.isfinite(js.by_name("position", m.scara.joint_names)).all(axis=1).any())


def has_swing(js: TopicArrays) -> bool:
    return bool(np.isfinite(js.by_name("position", [SWING])).any())
