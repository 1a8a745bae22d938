"""Summary and plots of a recorded excavator run (the demo's digging cycle), read back from its bag.

Figures in the manner of the paper's Fig. 11 (bucket position, velocity and acceleration in x, y,
z and alpha against time) and Fig. 12 (cylinder lengths, rates and accelerations against time),
with the reference dashed and the phases of the cycle shaded. Tracking errors are taken at equal
stamps of ``bucket_pose`` / ``reference_bucket_pose`` (and the twists), the path deviation as the
distance of each measured tip position from the reference polyline (timing aside); alpha, its rate and
acceleration come from ``open_chain_joint_states`` (alpha = theta2 + theta3 + theta4, eq. 3) and
``bucket_accel``; cylinder accelerations are differences of the recorded rates (3-sample moving
average).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from scipy.ndimage import median_filter

from excavator_kinematics.core.kinematics import CYLINDERS, JOINTS, Excavator
from excavator_kinematics.core.twist import boom_plane_normal, bucket_angles
from excavator_kinematics.demo.bucket_path import BucketPath, path_deviation
from manipulator_kinematics.bag.reader import BagReader, TopicArrays

AT_LIMIT_SPEED = 0.99  # fraction of the maximum speed that counts as "at the speed limit"
AT_LIMIT_STROKE = 1e-3  # m (rad for the swing) from an end that counts as "at the stroke end"
COLORS = ("tab:blue", "tab:orange", "tab:green")


@dataclass(frozen=True)
class Summary:
    text: str
    max_path_deviation: float  # m


def _vector(arrays: TopicArrays, prefix: str) -> np.ndarray:
    return np.stack([arrays[f"{prefix}.{axis}"] for axis in "xyz"], axis=-1)


def _until(arrays: TopicArrays, end_ns: int | None) -> TopicArrays:
    """The messages stamped up to ``end_ns`` (all for None or a topic without a header)."""
    if end_ns is None or "header.stamp.sec" not in arrays.fields:
        return arrays
    keep = arrays.stamp_ns() <= end_ns
    return TopicArrays(
        arrays.topic,
        arrays.msgtype,
        arrays.log_time[keep],
        {path: values[keep] for path, values in arrays.fields.items()},
    )


def _matched(a: TopicArrays, b: TopicArrays) -> tuple[np.ndarray, np.ndarray]:
    """Row indices of ``a`` and ``b`` with equal header stamps."""
    _, ia, ib = np.intersect1d(a.stamp_ns(), b.stamp_ns(), return_indices=True)
    return ia, ib


def _time_where(t: np.ndarray, condition: np.ndarray) -> float:
    """Seconds during which ``condition`` held (each sample counts until the next)."""
    return float(np.sum(np.diff(t)[condition[:-1]]))


def _smooth(values: np.ndarray, samples: int = 3) -> np.ndarray:
    """Centred moving average over ``samples`` rows: differences of sampled rates carry the timing
    jitter of the samples."""
    kernel = np.ones(samples) / samples
    if values.ndim == 1:
        return np.convolve(values, kernel, mode="same")
    return np.stack([np.convolve(column, kernel, mode="same") for column in values.T], axis=1)


#: Samples of the running median that sets an acceleration axis: 90 ms at the demo's 100 Hz,
#: wider than a stall's spike (a few samples), narrower than any motion of the cycle.
SPIKE_WINDOW = 9


def spike_limit(values: np.ndarray) -> float:
    """Half-height of an axis that shows the signal of ``values`` (samples along axis 0), not its
    spikes: 1.2 x the largest |running median| over SPIKE_WINDOW samples. A stall on a loaded
    machine (a late rate, a command timeout) makes acceleration spikes of +-240 deg/s^2 on a
    +-20 deg/s^2 signal; a percentile would follow them once they pass its share of the samples,
    the median does not while each lasts under half the window."""
    columns = np.asarray(values, dtype=float).reshape(len(values), -1)
    peak = 0.0
    for column in columns.T:
        column = column[np.isfinite(column)]
        if column.size:
            peak = max(peak, float(np.max(np.abs(median_filter(column, SPIKE_WINDOW, mode="nearest")))))
    return 1.2 * peak


def _clip_spikes(ax: plt.Axes, values: np.ndarray) -> None:
    """Scale an acceleration axis to its signal (:func:`spike_limit`); the samples beyond it are
    counted in a note on the axis."""
    limit = spike_limit(values)
    off = int(np.sum(np.abs(values[np.isfinite(values)]) > limit))
    if limit > 0.0 and off:
        ax.set_ylim(-limit, limit)
        ax.text(
            0.99,
            0.03,
            f"axis clipped at +-{limit:.3g}: {off} samples off-scale (stall spikes)",
            transform=ax.transAxes,
            ha="right",
            fontsize=8,
            color="0.3",
        )


def _shade(axes: np.ndarray, path: BucketPath, label_row: np.ndarray) -> None:
    """Alternate phases shaded, their names above ``label_row``; the time axis is the cycle's."""
    for ax in axes.flat:
        ax.set_xlim(0.0, path.duration + 1.0)
    for k, segment in enumerate(path.segments):
        t0, t1 = path.starts[k], path.starts[k + 1]
        for ax in axes.flat:
            if k % 2 == 0:
                ax.axvspan(t0, t1, color="0.93", zorder=0)
        for ax in label_row:
            ax.text(
                0.5 * (t0 + t1),
                1.02,
                segment.name,
                transform=ax.get_xaxis_transform(),
                ha="center",
                va="bottom",
                fontsize=7,
                color="0.3",
            )


def report(
    bag: Path, output: Path, exc: Excavator, path: BucketPath, start_ns: int, end_ns: int | None = None
) -> Summary:
    """Read ``bag``, write fig11_bucket.png and fig12_cylinders.png to ``output``, return the summary.
    The path deviation counts the bucket poses stamped from ``start_ns`` to ``end_ns`` (the cycle;
    default: to the end of the bag), not the hold before it or the stop after it; every topic is
    cut at ``end_ns`` (what the demo does after the cycle, the planned move, is not the cycle's)."""
    a = {topic: _until(arrays, end_ns) for topic, arrays in BagReader(bag).arrays().items()}
    pose, ref_pose = a["/bucket_pose"], a["/reference_bucket_pose"]
    twist, ref_twist = a["/bucket_twist"], a["/reference_bucket_twist"]
    accel, joints = a["/bucket_accel"], a["/open_chain_joint_states"]
    cylinders, swing = a["/cylinder_lengths"], a["/joint_states"]

    def seconds(arrays: TopicArrays) -> np.ndarray:
        return (arrays.stamp_ns() - start_ns) * 1e-9

    # Tracking errors at equal stamps.
    ip, ir = _matched(pose, ref_pose)
    position_error = np.linalg.norm(
        _vector(pose, "pose.position")[ip] - _vector(ref_pose, "pose.position")[ir], axis=1
    )
    in_cycle = (pose.stamp_ns() >= start_ns) & (end_ns is None or pose.stamp_ns() <= end_ns)
    deviation = path_deviation(
        _vector(pose, "pose.position")[in_cycle],
        seconds(pose)[in_cycle],
        _vector(ref_pose, "pose.position"),
        seconds(ref_pose),
    )
    quaternion = [f"pose.orientation.{c}" for c in "xyzw"]
    _, alpha = bucket_angles(np.stack([pose[c] for c in quaternion], axis=-1)[ip])
    _, ref_alpha = bucket_angles(np.stack([ref_pose[c] for c in quaternion], axis=-1)[ir])
    alpha_error = np.abs(np.angle(np.exp(1j * (alpha - ref_alpha))))
    it, irt = _matched(twist, ref_twist)
    velocity_error = np.linalg.norm(
        _vector(twist, "twist.linear")[it] - _vector(ref_twist, "twist.linear")[irt], axis=1
    )

    # Actuators: D = [theta1, d2, d3, d4] and rates, on the cylinder stamps.
    t_cyl = seconds(cylinders)
    lengths, rates = cylinders.by_name("position", CYLINDERS), cylinders.by_name("velocity", CYLINDERS)
    t_swing = seconds(swing)
    swing_angle, swing_rate = (
        swing.by_name("position", JOINTS[:1])[:, 0],
        swing.by_name("velocity", JOINTS[:1])[:, 0],
    )
    lim = exc.limits
    peak = np.r_[np.max(np.abs(swing_rate)), np.max(np.abs(rates), axis=0)]
    at_speed = [_time_where(t_swing, np.abs(swing_rate) >= AT_LIMIT_SPEED * lim.max_swing_speed)] + [
        _time_where(t_cyl, np.abs(rates[:, i]) >= AT_LIMIT_SPEED * lim.max_cylinder_speed[i])
        for i in range(3)
    ]
    at_stroke = [
        _time_where(
            t_swing, np.minimum(swing_angle - lim.swing_min, lim.swing_max - swing_angle) <= AT_LIMIT_STROKE
        )
    ] + [
        _time_where(
            t_cyl,
            np.minimum(lengths[:, i] - lim.stroke_min[i], lim.stroke_max[i] - lengths[:, i])
            <= AT_LIMIT_STROKE,
        )
        for i in range(3)
    ]

    names = ("swing", "boom", "arm", "bucket")
    units = ("rad/s", "m/s", "m/s", "m/s")
    lines = [
        f"excavator_demo: {path.duration:.1f} s digging cycle of the {exc.name}, "
        f"{sum(len(v) for v in a.values())} messages in {bag}",
        f"  bucket distance from the reference path: RMS {1e3 * np.sqrt(np.mean(deviation**2)):.1f} mm, "
        f"max {1e3 * deviation.max():.1f} mm",
        f"  bucket position error vs the reference at the same stamp: "
        f"RMS {1e3 * np.sqrt(np.mean(position_error**2)):.1f} mm, max {1e3 * position_error.max():.1f} mm",
        f"  bucket angle error: max {np.degrees(alpha_error.max()):.2f} deg",
        f"  bucket velocity tracking error |v - v_ref|: RMS {np.sqrt(np.mean(velocity_error**2)):.3f} m/s, "
        f"max {velocity_error.max():.3f} m/s",
        "  actuator   peak speed            time at speed limit   time at stroke end",
    ]
    for i, name in enumerate(names):
        lines.append(
            f"  {name:<9}  {peak[i]:.3f} / {lim.max_rates[i]:.2f} {units[i]:<6}  "
            f"{at_speed[i]:6.2f} s              {at_stroke[i]:6.2f} s"
        )

    _figure_bucket(
        output / "fig11_bucket.png", path, seconds, pose, ref_pose, twist, ref_twist, accel, joints
    )
    _figure_cylinders(
        output / "fig12_cylinders.png", path, exc, t_cyl, lengths, rates, t_swing, swing_angle, swing_rate
    )
    lines.append(f"  plots: {output / 'fig11_bucket.png'}, {output / 'fig12_cylinders.png'}")
    return Summary("\n".join(lines), float(deviation.max()))


def _figure_bucket(
    file: Path, path: BucketPath, seconds, pose, ref_pose, twist, ref_twist, accel, joints
) -> None:
    """Fig. 11 style: bucket tip x, y, z and bucket angle alpha; position, velocity, acceleration."""
    fig, axes = plt.subplots(3, 2, figsize=(13, 9), sharex=True, gridspec_kw={"width_ratios": [2, 1]})
    t_joint = seconds(joints)
    theta, theta_dot = joints["position"], joints["velocity"]
    alpha = np.degrees(theta[:, 1:].sum(axis=1))
    alpha_dot = np.degrees(theta_dot[:, 1:].sum(axis=1))
    t_acc = seconds(accel)
    theta1_acc = np.interp(t_acc, t_joint, theta[:, 0])
    alpha_ddot = np.degrees(np.sum(_vector(accel, "accel.angular") * boom_plane_normal(theta1_acc), axis=1))
    _, ref_alpha = bucket_angles(np.stack([ref_pose[f"pose.orientation.{c}"] for c in "xyzw"], axis=-1))
    ref_alpha = np.degrees(np.unwrap(ref_alpha))
    ref_alpha += 360.0 * np.round((alpha[0] - ref_alpha[0]) / 360.0)  # same turn as the measured alpha
    ref_rows = (_vector(ref_pose, "pose.position"), _vector(ref_twist, "twist.linear"), None)
    rows = (
        (seconds(pose), _vector(pose, "pose.position"), "position (m)", alpha, "alpha (deg)"),
        (seconds(twist), _vector(twist, "twist.linear"), "velocity (m/s)", alpha_dot, "alpha rate (deg/s)"),
        (t_acc, _vector(accel, "accel.linear"), "acceleration (m/s²)", alpha_ddot, "alpha accel. (deg/s²)"),
    )
    for r, (t, xyz, label, angle, angle_label) in enumerate(rows):
        left, right = axes[r]
        for k, axis in enumerate("xyz"):
            left.plot(t, xyz[:, k], color=COLORS[k], lw=1.2, label=axis)
            if ref_rows[r] is not None:
                t_ref = seconds(ref_pose if r == 0 else ref_twist)
                left.plot(t_ref, ref_rows[r][:, k], color=COLORS[k], lw=0.9, ls="--")
        right.plot(t_joint if r < 2 else t, angle, color="tab:red", lw=1.2, label="alpha")
        if r == 0:
            right.plot(seconds(ref_pose), ref_alpha, color="tab:red", lw=0.9, ls="--", label="reference")
        left.set_ylabel(label)
        right.set_ylabel(angle_label)
        for ax in (left, right):
            ax.grid(True, lw=0.3)
    _clip_spikes(axes[2, 0], _vector(accel, "accel.linear"))
    _clip_spikes(axes[2, 1], alpha_ddot)
    axes[0, 0].legend(
        loc="upper right", ncol=4, fontsize=8, title="solid: measured, dashed: reference", title_fontsize=8
    )
    axes[0, 1].legend(loc="upper right", fontsize=8)
    _finish(fig, axes, path, "Bucket tip in the base frame during a digging cycle (cf. paper Fig. 11)", file)


def _figure_cylinders(
    file: Path,
    path: BucketPath,
    exc: Excavator,
    t: np.ndarray,
    lengths: np.ndarray,
    rates: np.ndarray,
    t_swing: np.ndarray,
    swing_angle: np.ndarray,
    swing_rate: np.ndarray,
) -> None:
    """Fig. 12 style: cylinder lengths, rates and accelerations (and the swing) for the given bucket path."""
    lim = exc.limits
    fig, axes = plt.subplots(3, 2, figsize=(13, 9), sharex=True, gridspec_kw={"width_ratios": [2, 1]})
    accelerations = _smooth(np.gradient(rates, t, axis=0))
    swing_acceleration = _smooth(np.gradient(swing_rate, t_swing))
    for k, name in enumerate(("boom", "arm", "bucket")):
        c = COLORS[k]
        axes[0, 0].plot(t, lengths[:, k], color=c, lw=1.2, label=name)
        for end in (lim.stroke_min[k], lim.stroke_max[k]):
            axes[0, 0].axhline(end, color=c, lw=0.7, ls=":")
        axes[1, 0].plot(t, rates[:, k], color=c, lw=1.2, label=name)
        axes[1, 0].axhline(lim.max_cylinder_speed[k], color=c, lw=0.7, ls=":")
        axes[1, 0].axhline(-lim.max_cylinder_speed[k], color=c, lw=0.7, ls=":")
        axes[2, 0].plot(t, accelerations[:, k], color=c, lw=1.0, label=name)
    axes[0, 1].plot(t_swing, np.degrees(swing_angle), color="tab:purple", lw=1.2, label="swing")
    axes[1, 1].plot(t_swing, np.degrees(swing_rate), color="tab:purple", lw=1.2)
    for sign in (1, -1):
        axes[1, 1].axhline(sign * np.degrees(lim.max_swing_speed), color="tab:purple", lw=0.7, ls=":")
    axes[2, 1].plot(t_swing, np.degrees(swing_acceleration), color="tab:purple", lw=1.0)
    _clip_spikes(axes[2, 0], accelerations)
    _clip_spikes(axes[2, 1], np.degrees(swing_acceleration))
    labels = (
        ("cylinder length (m)", "swing angle (deg)"),
        ("cylinder rate (m/s)", "swing rate (deg/s)"),
        ("cylinder accel. (m/s²)", "swing accel. (deg/s²)"),
    )
    for r, (left, right) in enumerate(labels):
        axes[r, 0].set_ylabel(left)
        axes[r, 1].set_ylabel(right)
        for ax in axes[r]:
            ax.grid(True, lw=0.3)
    axes[0, 0].legend(
        loc="upper right", ncol=3, fontsize=8, title="dotted: stroke ends / max speeds", title_fontsize=8
    )
    _finish(fig, axes, path, "Swing and cylinders for the commanded bucket motion (cf. paper Fig. 12)", file)


def _finish(fig: plt.Figure, axes: np.ndarray, path: BucketPath, title: str, file: Path) -> None:
    """Time axis labels, the phases shaded, the title; saved and closed."""
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    _shade(axes, path, axes[0, :1])
    fig.suptitle(title, y=0.995)
    fig.tight_layout()
    fig.savefig(file, dpi=110)
    plt.close(fig)
