"""What ``evaluate`` computes from a bag: numpy over all messages at once, no rclpy, no machine.

For each topic: message rate, gaps and latency (record time minus header stamp) (:func:`topic_stats`).
For each machine found in a namespace of the bag: its ``analyse`` hook (see
:mod:`manipulator_kinematics.registry`) checks the published outputs against the kinematics
recomputed by the numpy core from the recorded inputs, matched by header stamp (the nodes stamp
outputs with their input's stamp). Serial machines share :func:`serial`; a machine with more to
check (the excavator's accelerations, command tracking and cylinder statistics) brings its own,
built on the helpers here. Errors are reported as max and RMS over matched messages
(:func:`error_stats`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from manipulator_kinematics.bag.reader import TopicArrays
from manipulator_kinematics.model import SerialModel, matrix_quaternion

# A gap longer than this many median periods counts as a gap in the topic statistics.
GAP_FACTOR = 2.5


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


@dataclass(frozen=True)
class AnalysisContext:
    """What a machine's ``analyse`` hook gets besides its topics and model.

    ``t0``: stamp origin (ns) of the time axes; ``prefix``: start of its plot names (namespace and
    machine, e.g. ``site_exc1_excavator_``); ``node_settings``: node name -> its settings (nested)
    from the package's config files, overridden by ``evaluate --params`` files.
    """

    t0: int
    prefix: str = ""
    node_settings: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)


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


def consistency_plot(plots: list[Plot], name: str, curves: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    """The |error| curves of a machine's outputs against the recomputed kinematics, if any."""
    if curves:
        panel = Panel("|published - recomputed|\n(unit per curve: legend)", curves, log=True)
        plots.append(Plot(name, "Published outputs vs recomputed kinematics", [panel]))


# ------------------------------------------------------------------------------------------ serial


def serial(
    data: dict[str, TopicArrays], model: SerialModel, context: AnalysisContext
) -> tuple[dict[str, Any], list[Plot]]:
    """The ``analyse`` hook of a serial machine (the generic forward node's topics).

    ``tool_pose`` against ``model.fkine`` (position and rotation angle) and ``tool_twist`` against
    ``model.jacob0 @ qd`` (linear and angular) of the ``joint_states`` message with the same stamp,
    and the number of joint states outside the joint limits.
    """
    report: dict[str, Any] = {}
    plots: list[Plot] = []
    if "joint_states" not in data:
        return report, plots
    js = data["joint_states"]
    names = tuple(model.joint_names)
    q, qd = js.by_name("position", names), js.by_name("velocity", names)
    rows = np.flatnonzero(np.all(np.isfinite(q), axis=1))
    stamp = js.stamp_ns()[rows]
    q, qd = q[rows], qd[rows]
    report["joint_states"] = len(rows)
    report["outside_limits"] = int(np.sum(~model.limits.within(q)))
    consistency: dict[str, Any] = {}
    curves: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def matched(topic: str) -> tuple[TopicArrays, np.ndarray, np.ndarray] | None:
        if topic not in data:
            return None
        arrays = data[topic]
        k = match_exact(arrays.stamp_ns(), stamp)
        got = np.flatnonzero(k >= 0)
        consistency[topic] = {"matched": int(got.size), "unmatched": int(len(arrays) - got.size)}
        return arrays, got, k[got]

    if found := matched("tool_pose"):
        pose, got, k = found
        expected = model.fkine(q[k]).reshape(-1, 4, 4)
        position = np.linalg.norm(vectors(pose, "pose.position")[got] - expected[:, :3, 3], axis=1)
        quaternion = np.stack([pose[f"pose.orientation.{a}"] for a in "xyzw"], axis=-1)[got]
        rotation = quaternion_angle(quaternion, matrix_quaternion(expected[:, :3, :3]))
        consistency["tool_pose"].update(
            position_m=error_stats(position), orientation_rad=error_stats(rotation)
        )
        curves["tool_pose position (m)"] = (since(pose.stamp_ns()[got], context.t0), position)
    if found := matched("tool_twist"):
        twist, got, k = found
        known = np.all(np.isfinite(qd[k]), axis=1)
        got, k = got[known], k[known]
        expected = np.einsum("nij,nj->ni", model.jacob0(q[k]).reshape(len(k), 6, -1), qd[k])
        linear = np.linalg.norm(vectors(twist, "twist.linear")[got] - expected[:, :3], axis=1)
        angular = np.linalg.norm(vectors(twist, "twist.angular")[got] - expected[:, 3:], axis=1)
        consistency["tool_twist"].update(linear_mps=error_stats(linear), angular_radps=error_stats(angular))
        curves["tool_twist linear (m/s)"] = (since(twist.stamp_ns()[got], context.t0), linear)
    if consistency:
        report["consistency"] = consistency
    consistency_plot(plots, f"{context.prefix}consistency", curves)
    return report, plots
