"""excavator_slope_example: the CET200 on a 5 % slope, on noisy IMUs, cutting a ditch of a design TIN.

An offline run of the chain a retrofit machine uses (no processes, no DDS; issue #21 item 4):

1. the site: a ditch (bottom 0.2 m wide, 1.5 m deep, side slopes 1:1) running up the
   slope straight ahead of the machine, written as LandXML 1.2 and read back
   (:mod:`excavator_kinematics.grade.design_surface`);
2. the machine stands on the slope (pitch atan 5 %, heading ``HEADING``) and drags the bucket
   toward itself along the ditch, 15 cm right of its axis, 15 cm above grade at the start down to
   2 cm, curling the bucket;
   its cylinder states come from the bucket path by the open chain's inverse (planar two-link IK
   for boom and arm, eq. 3) and :meth:`Excavator.cylinder_lengths`;
3. the four IMUs read that motion with noise (:func:`excavator_kinematics.sensing.imu.simulated_readings`:
   0.05 deg per axis on each orientation, 0.005 rad/s on each gyro), and
   :class:`excavator_kinematics.sensing.imu.ImuArm` turns the readings back into cylinder lengths;
4. forward kinematics, the cutting edge in the site frame and its heights above the TIN, for the
   estimate and for the truth. The estimate places the machine on the site as a retrofit does:
   ``site`` -> ``base_level`` from the machine's position and heading (GNSS; here exact), and
   ``base_level`` -> ``base_link`` from the cab IMU's tilt (``machine_tilt``, noisy).

Writes to ``--output`` (default out/slope_example): ``ditch.xml``; ``bag/`` (rosbag2, mcap) with
the IMU messages, cylinder_lengths (from the IMUs), joint_states, bucket_pose, grade/tip|left|right
(PointStamped, z = height above the TIN), ``machine_tilt``, ``bucket_pose_site`` (the estimate's
bucket pose in ``site``) and ``design_surface`` (visualization_msgs/Marker TRIANGLE_LIST in frame
``site``, the surface as a mesh), and the bag visuals (:func:`manipulator_kinematics.bag.visual.add_visuals`:
robot_description, /tf with base_level -> base_link from machine_tilt, /tf_static with
site -> base_level): open the bag in Foxglove, set the 3D panel's display frame to ``site`` and
plot ``/grade/tip.point.z``, ``/grade/left.point.z``, ``/grade/right.point.z``;
``grade_heights.png``, the tip and corner heights along the cut.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from excavator_kinematics.core.kinematics import CYLINDERS, JOINTS, Excavator, bucket_quaternion
from excavator_kinematics.grade.design_surface import SitePose, Tin, cutting_edge, read_landxml, write_landxml
from excavator_kinematics.sensing.imu import (
    SENSORS,
    ImuArm,
    base_up,
    level_rotation,
    simulated_readings,
    up_from_orientation,
)
from manipulator_kinematics.model import pose_matrix
from manipulator_kinematics.planar import ELBOW_NEGATIVE, two_link_ik

SLOPE = 0.05  # rise per run of the ground, ahead of the machine
HEADING = 0.6  # rad, the machine's heading in the site frame (x east)
SITE = np.array([512_300.0, 5_402_100.0, 231.4])  # base_link in the site frame (m)
DEPTH, BOTTOM, SIDE = 1.5, 0.2, 1.0  # ditch depth, bottom width (m), side slope run per rise
OFFSET = -0.15  # m, the cut's side offset from the ditch axis (base y, left +)
SITE_FRAME = "site"


def ditch(start: float = 2.0, end: float = 12.0) -> Tin:
    """The design in the site frame: the ditch along the heading, from ``start`` to ``end`` m
    ahead, following the 5 % ground; banks 4 m wide either side."""
    offsets = np.array(
        [
            -0.5 * BOTTOM - SIDE * DEPTH - 4.0,
            -0.5 * BOTTOM - SIDE * DEPTH,
            -0.5 * BOTTOM,
            0.5 * BOTTOM,
            0.5 * BOTTOM + SIDE * DEPTH,
            0.5 * BOTTOM + SIDE * DEPTH + 4.0,
        ]
    )
    depth = np.array([0.0, 0.0, DEPTH, DEPTH, 0.0, 0.0])
    along = np.linspace(start, end, 6)
    s, o = np.meshgrid(along, offsets, indexing="ij")
    forward = np.array([math.cos(HEADING), math.sin(HEADING)])
    left = np.array([-math.sin(HEADING), math.cos(HEADING)])
    xy = SITE[:2] + s[..., None] * forward + o[..., None] * left
    z = SITE[2] + SLOPE * s - depth
    vertices = np.column_stack([xy.reshape(-1, 2), z.reshape(-1)])
    m = len(offsets)
    cells = [(i * m + j, (i + 1) * m + j) for i in range(len(along) - 1) for j in range(m - 1)]
    faces = [[a, a + 1, b + 1] for a, b in cells] + [[a, b + 1, b] for a, b in cells]
    return Tin(vertices, np.array(faces), "Ditch design")


def cut(exc: Excavator, seconds: float, rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times (N,), D (N, 4) and D_dot (N, 4) of the cut: the tip along the ditch from 7 m to
    3.5 m ahead, from 0.15 m to 0.02 m above grade, the bucket angle from -110 to -150 deg."""
    t = np.arange(int(seconds * rate) + 1) / rate
    phase = 0.5 - 0.5 * np.cos(np.pi * t / seconds)  # smooth start and stop
    ahead = 7.0 - 3.5 * phase
    above = 0.15 - 0.13 * phase
    alpha = np.radians(-110.0 - 40.0 * phase)
    # The ditch bottom follows the ground, which the base frame is parallel to: in base_link the
    # bottom is at z = -DEPTH cos(slope angle) (1.498 m), whatever the slope.
    # 0.15 m right of the ditch axis (the swing turns the boom plane there): the tip 0.05 m, the
    # left corner 0.25 m and the right one 0.55 m up the side slopes.
    r, swing = np.hypot(ahead, OFFSET), np.arctan2(OFFSET, ahead)
    z = above - DEPTH * math.cos(math.atan(SLOPE))
    wrist_r, wrist_z = r - exc.l4 * np.cos(alpha), z - exc.l4 * np.sin(alpha)
    arm = two_link_ik(wrist_r - exc.l1, wrist_z - exc.l0, exc.l2, exc.l3)
    theta2, theta3 = arm.theta1[:, ELBOW_NEGATIVE], arm.theta2[:, ELBOW_NEGATIVE]
    lengths = exc.cylinder_lengths(np.column_stack([theta2, theta3, alpha - theta2 - theta3]))
    D = np.column_stack([swing, lengths])
    return t, D, np.gradient(D, t, axis=0)


def heights(exc: Excavator, tin: Tin, site: SitePose, D: np.ndarray) -> np.ndarray:
    """Heights (N, 3) of tip, left and right end of the cutting edge above the TIN (NaN outside)."""
    edge = site.apply(cutting_edge(exc.pose(D)[:, :3], D[:, 0], exc.bucket_width))
    return tin.heights(edge).height


def run(output: Path, seconds: float = 8.0, rate: float = 50.0, seed: int = 21) -> dict[str, float]:
    """The whole example; returns the RMS and max height error of the IMU estimate (m)."""
    from manipulator_kinematics.bag.asbuilt import process_bag
    from manipulator_kinematics.bag.synthetic import Topic, write_bag
    from manipulator_kinematics.bag.visual import LEVEL_FRAME, add_visuals
    from manipulator_kinematics.codec.packed import serialize_unpadded

    exc = Excavator.default()
    output.mkdir(parents=True, exist_ok=True)
    write_landxml(output / "ditch.xml", ditch())
    tin = read_landxml(output / "ditch.xml")
    tilt = (0.0, -math.atan(SLOPE), HEADING)  # nose up on the rising ground
    site = SitePose.from_rpy(SITE, tilt)
    t, D, D_dot = cut(exc, seconds, rate)
    arm = ImuArm(exc)
    rng = np.random.default_rng(seed)
    q, omega, f = simulated_readings(arm, D, D_dot, tilt, rng, math.radians(0.05), 0.005)
    estimate = arm.joints(up_from_orientation(q), omega)
    D_imu = np.column_stack([D[:, 0], estimate.lengths])
    # The machine's place on the site: position and heading (site -> base_level), then the cab
    # IMU's tilt (base_level -> base_link, p_level = R p_base) at each sample.
    heading = pose_matrix(SITE, [0.0, 0.0, math.sin(HEADING / 2), math.cos(HEADING / 2)])
    imu_site = SitePose(heading[:3, :3] @ level_rotation(base_up(estimate.up_cab, D_imu[:, 0])), SITE)
    true, got = heights(exc, tin, site, D), heights(exc, tin, imu_site, D_imu)
    error = got - true
    stamps = (1_700_000_000 * 10**9 + np.round(t * 1e9)).astype(np.int64)
    topics = _messages(
        exc, tin, stamps, q, omega, f, D_imu, estimate.rates, D_dot[:, 0], imu_site, got, estimate.up_cab
    )
    write_bag(
        output / "bag",
        {
            name: Topic(
                kind,
                np.array([_stamp_ns(m) for m in messages], dtype=np.int64),
                [serialize_unpadded(m) for m in messages],
            )
            for name, (kind, messages) in topics.items()
        },
        overwrite=True,
    )
    add_visuals(output / "bag", output / "bag", extra_static=[(SITE_FRAME, LEVEL_FRAME, heading)])
    tip_x = exc.pose(D)[:, 0]
    _plot(output / "grade_heights.png", tip_x[0] - tip_x, true, got)
    # What the bucket dug: mk_asbuilt's tables and surfaces, with the forward node's settings for
    # this site (the design and where the machine stands) in a params file beside the bag.
    settings = output / "asbuilt_params.yaml"
    settings.write_text(
        yaml.safe_dump(
            {
                "/**/excavator_forward": {
                    "ros__parameters": {
                        "design_surface": {
                            "file": str(output / "ditch.xml"),
                            "site_position": SITE.tolist(),
                            "site_rpy": list(tilt),
                        }
                    }
                }
            }
        )
    )
    asbuilt = process_bag(output / "bag", output / "asbuilt", [settings], cell=0.1)
    if asbuilt.error:
        raise RuntimeError(f"as-built of the example's own bag: {asbuilt.error}")
    return {
        "rms_m": float(np.sqrt(np.mean(error**2))),
        "max_m": float(np.max(np.abs(error))),
        "samples": len(t),
    }


def _stamp_ns(message) -> int:
    return message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec


def _messages(
    exc, tin, stamps, q, omega, f, D_imu, rates, swing_rate, site, grade, up_cab
) -> dict[str, tuple[str, list]]:
    """Every topic of the bag: type and messages (rclpy message objects); ``site``: the
    estimate's base_link in the site frame at each sample."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Point, PointStamped, PoseStamped, Vector3, Vector3Stamped
    from sensor_msgs.msg import Imu, JointState
    from std_msgs.msg import ColorRGBA, Header
    from visualization_msgs.msg import Marker

    def header(stamp: int, frame: str = "") -> Header:
        return Header(stamp=Time(sec=int(stamp // 10**9), nanosec=int(stamp % 10**9)), frame_id=frame)

    out: dict[str, tuple[str, list]] = {}
    for i, name in enumerate(SENSORS):
        messages = []
        for k, stamp in enumerate(stamps.tolist()):
            m = Imu(header=header(stamp, f"imu_{name}"))
            m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w = q[k, i].tolist()
            m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = omega[k, i].tolist()
            m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z = f[k, i].tolist()
            messages.append(m)
        out[f"/imu/{name}"] = ("sensor_msgs/msg/Imu", messages)
    out["/joint_states"] = (
        "sensor_msgs/msg/JointState",
        [
            JointState(header=header(s), name=[JOINTS[0]], position=[d[0]], velocity=[v])
            for s, d, v in zip(stamps.tolist(), D_imu.tolist(), swing_rate.tolist(), strict=True)
        ],
    )
    out["/cylinder_lengths"] = (
        "sensor_msgs/msg/JointState",
        [
            JointState(header=header(s), name=list(CYLINDERS), position=d[1:].tolist(), velocity=v.tolist())
            for s, d, v in zip(stamps.tolist(), D_imu, rates, strict=True)
        ],
    )
    Q = exc.pose(D_imu)
    poses = []
    for s, d, pose in zip(stamps.tolist(), D_imu, Q, strict=True):
        p = PoseStamped(header=header(s, "base_link"))
        p.pose.position.x, p.pose.position.y, p.pose.position.z = pose[:3].tolist()
        o = bucket_quaternion(float(d[0]), float(pose[3])).tolist()
        p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z, p.pose.orientation.w = o
        poses.append(p)
    out["/bucket_pose"] = ("geometry_msgs/msg/PoseStamped", poses)
    out["/machine_tilt"] = (
        "geometry_msgs/msg/Vector3Stamped",
        [
            Vector3Stamped(header=header(s, "upper_structure"), vector=Vector3(x=u[0], y=u[1], z=u[2]))
            for s, u in zip(stamps.tolist(), up_cab.tolist(), strict=True)
        ],
    )
    tip_site = site.apply(Q[:, None, :3])[:, 0]
    turn = Rotation.from_matrix(site.rotation)
    in_base = Rotation.from_quat(
        [
            [p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z, p.pose.orientation.w]
            for p in poses
        ]
    )
    site_poses = []
    for s, tip, o in zip(stamps.tolist(), tip_site, (turn * in_base).as_quat(), strict=True):
        m = PoseStamped(header=header(s, SITE_FRAME))
        m.pose.position.x, m.pose.position.y, m.pose.position.z = tip.tolist()
        m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w = o.tolist()
        site_poses.append(m)
    out["/bucket_pose_site"] = ("geometry_msgs/msg/PoseStamped", site_poses)
    edge = site.apply(cutting_edge(Q[:, :3], D_imu[:, 0], exc.bucket_width))
    for i, name in enumerate(("tip", "left", "right")):
        out[f"/grade/{name}"] = (
            "geometry_msgs/msg/PointStamped",
            [
                PointStamped(
                    header=header(s, SITE_FRAME),
                    point=Point(x=float(e[i, 0]), y=float(e[i, 1]), z=float(h[i])),
                )
                for s, e, h in zip(stamps.tolist(), edge, grade, strict=True)
                if np.isfinite(h[i])
            ],
        )
    # The surface as a mesh, relative to the TIN's own origin (Marker points are float64, but a
    # viewer renders in float32: UTM coordinates would lose centimetres).
    local = tin.vertices - tin.origin
    mesh = Marker(
        header=header(int(stamps[0]), SITE_FRAME),
        ns="design_surface",
        id=0,
        type=Marker.TRIANGLE_LIST,
        action=Marker.ADD,
        frame_locked=False,
    )
    mesh.pose.position.x, mesh.pose.position.y, mesh.pose.position.z = tin.origin.tolist()
    mesh.pose.orientation.w = 1.0
    mesh.scale.x = mesh.scale.y = mesh.scale.z = 1.0
    mesh.color = ColorRGBA(r=0.55, g=0.45, b=0.3, a=0.8)
    corners = local[tin.faces.reshape(-1)].tolist()
    mesh.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in corners]
    out["/design_surface"] = ("visualization_msgs/msg/Marker", [mesh])
    return out


def _plot(path: Path, distance: np.ndarray, true: np.ndarray, got: np.ndarray) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 5))
    lines = (("tip", "k"), ("left corner", "tab:blue"), ("right corner", "tab:red"))
    for i, (name, color) in enumerate(lines):
        ax.plot(distance, 100 * got[:, i], color=color, lw=1, label=f"{name}, from the IMUs (noise)")
        ax.plot(distance, 100 * true[:, i], color=color, lw=2, ls="--", alpha=0.6, label=f"{name}, true")
    ax.axhline(0.0, color="saddlebrown", lw=1)
    ax.set_xlabel("distance along the cut (m)")
    ax.set_ylabel("height above the design TIN (cm)")
    ax.set_title(
        "CET200 on a 5 % slope cutting a TIN ditch (bottom 0.2 m, sides 1:1, bucket 1.0 m) 0.15 m\n"
        "right of its axis: tip, left and right corner 0.05, 0.25, 0.55 m up the side slopes; "
        "IMU noise 0.05 deg/axis, gyro 0.005 rad/s",
        fontsize=10,
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="excavator_slope_example", description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path, default=Path("out/slope_example"))
    parser.add_argument("--seconds", type=float, default=8.0, help="duration of the cut (s)")
    parser.add_argument("--rate", type=float, default=50.0, help="IMU rate (Hz)")
    args = parser.parse_args(argv)
    result = run(args.output, args.seconds, args.rate)
    print(
        f"{result['samples']} samples; grade height error of the IMU estimate: RMS "
        f"{1000 * result['rms_m']:.1f} mm, max {1000 * result['max_m']:.1f} mm; wrote {args.output}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
