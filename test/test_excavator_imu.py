"""Cylinder states from inclination sensors (excavator_kinematics.sensing.imu): IMU readings generated from
known states (orientation, gyro and gravity in each sensor's frame, mounting rotations, a tilted
machine, a different heading per sensor) give back the cylinder lengths and rates."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from excavator_kinematics.core.kinematics import Excavator, StrokeError
from excavator_kinematics.grade.design_surface import read_landxml
from excavator_kinematics.sensing.imu import (
    GRAVITY,
    MAX_SIDEWAYS_TILT,
    SENSORS,
    ImuArm,
    TiltFilter,
    base_up,
    level_rotation,
    simulated_readings,
    up_from_acceleration,
    up_from_orientation,
)

EXC = Excavator.default()
LIM = EXC.limits
RNG = np.random.default_rng(2101)
MOUNTINGS = {
    "cab": [0.03, -0.02, 1.2],
    "boom": [-math.pi / 2, 0.1, 0.05],
    "arm": [math.pi, 0.0, -0.3],
    "bucket_linkage": [0.2, -0.4, 2.5],
}


def imu_section(body: str) -> dict:
    return {
        name: {"rotation_rpy": MOUNTINGS[name], **({"body": body} if name == "bucket_linkage" else {})}
        for name in SENSORS
    }


def side_angles(D: np.ndarray, body: str, step: float = 0.0, D_dot: np.ndarray | None = None) -> np.ndarray:
    """Absolute side angles (4,) of cab, boom, arm and the linkage body relative to the upper
    structure, from the model's pins (independent of imu.py): 0, theta2, theta2 + theta3 and the
    bucket's (theta2..4 summed) or the H-link's direction rod pin -> H-link pin."""
    D = D + (step * D_dot if D_dot is not None else 0.0)
    theta = EXC.state(D, np.zeros(4)).theta
    pins = EXC.pins(D)
    c, s = math.cos(D[0]), math.sin(D[0])
    h = pins["h_link_pin"] - pins["bucket_cylinder_rod"]
    h_angle = math.atan2(h[2], h[0] * c + h[1] * s)
    last = theta[1] + theta[2] + theta[3] if body == "bucket" else h_angle
    return np.array([0.0, theta[1], theta[1] + theta[2], last])


def readings(D, D_dot, body, tilt=(0.06, -0.05, 0.4), mountings=MOUNTINGS):
    """Quaternions [x, y, z, w], angular velocities and specific forces (4, ...) in each sensor's
    frame. World <- base_link: the machine's roll, pitch, yaw; <- upper structure: the swing;
    <- body: a turn of the side angle about -y; <- sensor: the mounting. Each IMU reports its
    orientation against its own heading (a different yaw per sensor)."""
    phi = side_angles(D, body)
    h = 1e-6
    phi_dot = (side_angles(D, body, h, D_dot) - side_angles(D, body, -h, D_dot)) / (2 * h)
    world_base = Rotation.from_euler("xyz", tilt)
    upper = world_base * Rotation.from_euler("z", D[0])
    omega_upper = world_base.apply([0.0, 0.0, D_dot[0]])
    quaternions, omegas, forces = [], [], []
    for i, name in enumerate(SENSORS):
        sensor = upper * Rotation.from_euler("y", -phi[i]) * Rotation.from_euler("xyz", mountings[name])
        omega_world = omega_upper + upper.apply([0.0, -phi_dot[i], 0.0])
        heading = Rotation.from_euler("z", 0.7 * i - 1.0)
        quaternions.append((heading * sensor).as_quat())
        omegas.append(sensor.inv().apply(omega_world))
        forces.append(sensor.inv().apply([0.0, 0.0, GRAVITY]))
    return np.array(quaternions), np.array(omegas), np.array(forces)


def states(n: int) -> tuple[np.ndarray, np.ndarray]:
    D = RNG.uniform(LIM.d_min, LIM.d_max, (n, 4))
    D[:, 0] = RNG.uniform(-3.0, 3.0, n)
    return D, RNG.uniform(-1, 1, (n, 4)) * LIM.max_rates


@pytest.mark.parametrize("body", ["h_link", "bucket"])
def test_imu_readings_give_back_the_cylinder_states(body):
    arm = ImuArm(EXC, imu_section(body))
    D, D_dot = states(60)
    # The whole stroke of each cylinder, to 1 um of its ends (the generator differences the pins
    # over +-0.2 um).
    D[:3, 1:] = [LIM.d_min[1:] + 1e-6, LIM.d_max[1:] - 1e-6, LIM.reference[1:]]
    for tilt in [(0.0, 0.0, 0.0), (0.06, -0.05, 0.4), (-0.2, 0.15, -2.0)]:
        data = [readings(d, v, body, tilt) for d, v in zip(D, D_dot, strict=True)]
        q, omega, f = (np.array([x[i] for x in data]) for i in range(3))
        by_orientation = arm.joints(up_from_orientation(q), omega)
        by_gravity = arm.joints(up_from_acceleration(f), omega)
        for got in (by_orientation, by_gravity):
            np.testing.assert_allclose(got.lengths, D[:, 1:], rtol=0, atol=1e-9)
            np.testing.assert_allclose(got.theta, EXC.joint_angles(D[:, 1:]), rtol=0, atol=1e-9)
            np.testing.assert_allclose(got.rates, D_dot[:, 1:], rtol=0, atol=1e-7)


def test_h_link_inverse_over_the_whole_stroke():
    """theta4 from the H-link angle along 2001 bucket lengths: the model's theta4 (eq. 2) and
    rate ratio k4, continuously on the assembly branch."""
    arm = ImuArm(EXC, imu_section("h_link"))
    lengths = np.tile(LIM.reference[1:], (2001, 1))
    lengths[:, 2] = np.linspace(LIM.stroke_min[2], LIM.stroke_max[2], 2001)
    D = np.column_stack([np.zeros(len(lengths)), lengths])
    pins = EXC.pins(D)
    theta = EXC.joint_angles(lengths)
    h = pins["h_link_pin"] - pins["bucket_cylinder_rod"]
    psi = np.arctan2(h[:, 2], h[:, 0]) - theta[:, 0] - theta[:, 1]
    theta4, ratio = arm.theta4_from_h_link(psi, np.ones_like(psi))
    np.testing.assert_allclose((theta4 - theta[:, 2] + np.pi) % (2 * np.pi) - np.pi, 0.0, atol=1e-9)
    # d theta4 / d psi by differences along the stroke, against the closed form.
    dtheta4 = np.gradient(np.unwrap(theta4), np.unwrap(psi))
    np.testing.assert_allclose(ratio[1:-1], dtheta4[1:-1], rtol=2e-4)


def test_noise_bound():
    """Orientation noise of sigma = 0.05 deg about each axis of each sensor (and accelerometer
    noise of 0.02 m/s^2 per axis on the gravity path): the length errors have the RMS first-order
    propagation predicts, sqrt(2) sigma_a |dd/dtheta| (two sensors per joint, only the rotation
    about y moves a side angle), within 15 %, and stay below 5 x that."""
    body = "bucket"
    arm = ImuArm(EXC, imu_section(body))
    D = LIM.reference + np.array([0.4, 0.1, -0.1, 0.05])
    q, omega, f = readings(D, np.zeros(4), body)
    n = 4000
    k, _ = EXC.k_entries(D[1:])
    sigma = math.radians(0.05)
    noise = Rotation.from_rotvec(RNG.normal(0.0, sigma, (n * 4, 3)))
    noisy_q = (Rotation.from_quat(np.tile(q, (n, 1))) * noise).as_quat()
    sigma_f = 0.02
    noisy_f = f + RNG.normal(0.0, sigma_f, (n, 4, 3))
    for up, sigma_a in (
        (up_from_orientation(noisy_q.reshape(n, 4, 4)), sigma),
        (up_from_acceleration(noisy_f), sigma_f / GRAVITY),
    ):
        error = arm.joints(up, np.tile(omega, (n, 1, 1))).lengths - D[1:]
        predicted = math.sqrt(2.0) * sigma_a / np.abs(k)
        rms = np.sqrt(np.mean(error**2, axis=0))
        np.testing.assert_allclose(rms, predicted, rtol=0.15)
        assert np.all(np.abs(error).max(axis=0) < 5.0 * predicted)
    # The bound in millimetres for this state (docs): sigma_a = 0.05 deg.
    assert np.all(math.sqrt(2.0) * sigma / np.abs(k) < 1.5e-3)


def test_tilt_filter_rejects_dynamic_acceleration():
    """A sensor at a fixed tilt shaken by 2 m/s^2 at 3 Hz along its x axis: the side angle from
    f / |f| swings by about 0.2 rad, the complementary filter (tau = 1 s, 100 Hz) stays within a
    tenth of that; at rest it converges to the exact angle."""
    true = Rotation.from_euler("xyz", [0.1, -0.3, 0.0])
    up_true = true.inv().apply([0.0, 0.0, 1.0])
    t = np.arange(0.0, 10.0, 0.01)
    shake = 2.0 * np.sin(2 * np.pi * 3.0 * t)
    raw_filter, filtered = TiltFilter(0.0), TiltFilter(1.0)
    raw, smooth = [], []
    for s in shake:
        f = true.inv().apply([0.0, 0.0, GRAVITY]) + [s, 0.0, 0.0]
        raw.append(raw_filter.update(0.01, np.zeros(3), f))
        smooth.append(filtered.update(0.01, np.zeros(3), f))
    angle = lambda u: np.arctan2(np.asarray(u)[:, 0], np.asarray(u)[:, 2])  # noqa: E731
    exact = math.atan2(up_true[0], up_true[2])
    raw_error = np.abs(angle(raw) - exact)[500:].max()
    smooth_error = np.abs(angle(smooth) - exact)[500:].max()
    assert raw_error > 0.15 and smooth_error < 0.1 * raw_error
    # Turning at 0.5 rad/s about y with a consistent gyro: the filter follows without lag bias.
    moving = TiltFilter(1.0)
    for i in range(300):
        body = true * Rotation.from_euler("y", 0.5 * i * 0.01)
        up = moving.update(0.01, [0.0, 0.5, 0.0], body.inv().apply([0.0, 0.0, GRAVITY]))
    expected = body.inv().apply([0.0, 0.0, 1.0])
    np.testing.assert_allclose(up, expected, atol=3e-4)


def test_a_machine_rolled_near_90_deg_gets_no_rates_it_cannot_have():
    """Issue 29 defect 2: rolled near 90 deg with 0.01 rad/s gyro noise, the cylinder rates were
    15.6 m/s to 1.6e7 m/s: the side angle's rate divides by ux^2 + uz^2, which vanishes when a
    sensor's y axis points up. A set beyond MAX_SIDEWAYS_TILT is refused with the reason; below it
    the noise stays well inside RATE_MARGIN x the speed limits."""
    from excavator_kinematics.nodes.imu_state_node import RATE_MARGIN

    arm = ImuArm(EXC, imu_section("h_link"))
    rng = np.random.default_rng(29)
    D, _ = states(50)
    D[:, 0] = 0.0  # the swing turns the boom plane against the roll: here the roll is its tilt
    bound = RATE_MARGIN * LIM.max_rates[1:]
    refused = 0
    for roll in np.radians([0.0, 20.0, 40.0, 55.0, 70.0, 85.0, 89.0, 89.9]):
        q, omega, _ = simulated_readings(arm, D, np.zeros_like(D), (roll, 0.0, 0.0), rng, 0.0, 0.01)
        up = up_from_orientation(q)
        sideways = np.degrees(np.arcsin(np.abs(np.einsum("sij,nsj->nsi", arm.mounting, up)[..., 1])))
        for k in range(len(D)):
            try:
                rates = arm.joints(up[k], omega[k]).rates
            except StrokeError as error:
                assert sideways[k].max() > math.degrees(MAX_SIDEWAYS_TILT)
                assert "sideways" in str(error) and "ill-conditioned" in str(error)
                refused += 1
                continue
            assert sideways[k].max() <= math.degrees(MAX_SIDEWAYS_TILT)
            assert np.all(np.abs(rates) < 0.5 * bound), (math.degrees(roll), rates)
    assert refused == 4 * len(D)  # every set at 70 deg and beyond


def test_level_frame_from_the_cab_imu_gives_heights_along_gravity():
    """Machine tilt (item 2): the cab IMU's up vector, turned into base_link by the swing, gives
    the level frame, in which every point's z is its height along gravity above base_link's origin
    (the world rotation applied by hand), its x axis is horizontal and under base_link's x."""
    arm = ImuArm(EXC, imu_section("h_link"))
    D, D_dot = states(20)
    for tilt in [(0.0, 0.0, 0.3), (0.087, -0.05, 1.0), (-0.12, 0.2, -2.5)]:
        world_base = Rotation.from_euler("xyz", tilt)
        for d, v in zip(D, D_dot, strict=True):
            q, omega, _ = readings(d, v, "h_link", tilt)
            up_cab = arm.joints(up_from_orientation(q), omega).up_cab
            R = level_rotation(base_up(up_cab, d[0]))
            pins = EXC.pins(d)
            for name in ("bucket_tip", "arm_pin", "h_link_pin"):
                p = pins[name]
                assert (R @ p)[2] == pytest.approx(world_base.apply(p)[2], abs=1e-12)
                assert np.linalg.norm(R @ p) == pytest.approx(np.linalg.norm(p), abs=1e-12)
            x_world = world_base.apply(R[0])
            assert x_world[2] == pytest.approx(0.0, abs=1e-12)
            base_x = world_base.apply([1.0, 0.0, 0.0])
            assert np.cross(base_x, x_world)[2] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(level_rotation([0.0, 0.0, 1.0]), np.eye(3), atol=0)


def test_mk_evaluate_checks_bucket_pose_level(tmp_path):
    """mk_evaluate recomputes bucket_pose_level from machine_tilt: exact messages give zero, a
    planted 2 mm error in 5 of 50 is reported as such."""
    from excavator_kinematics.tools.synthetic import excavator_bag
    from manipulator_kinematics.bag.evaluate import Setup, evaluate_bag
    from manipulator_kinematics.bag.reader import BagReader
    from manipulator_kinematics.bag.synthetic import Topic, write_bag
    from manipulator_kinematics.bag.types import decode_messages, encode_messages

    topics = excavator_bag(EXC, 50, 50.0)
    pose = topics["/bucket_pose"]
    fields = decode_messages(pose.msgtype, pose.raw)
    n = len(pose.raw)
    up_cab = Rotation.from_euler("xyz", [0.04, -0.06, 0.0]).inv().apply([0.0, 0.0, 1.0])
    cylinders = decode_messages("sensor_msgs/msg/JointState", topics["/cylinder_lengths"].raw)
    stamp = {k: np.asarray(cylinders[k]) for k in ("header.stamp.sec", "header.stamp.nanosec")}
    tilt = {
        **stamp,
        "header.frame_id": "upper_structure",
        **{f"vector.{a}": np.full(n, up_cab[i]) for i, a in enumerate("xyz")},
    }
    topics["/machine_tilt"] = Topic(
        "geometry_msgs/msg/Vector3Stamped",
        pose.log_time,
        encode_messages("geometry_msgs/msg/Vector3Stamped", n, tilt),
    )
    joints = decode_messages("sensor_msgs/msg/JointState", topics["/open_chain_joint_states"].raw)
    theta1 = np.asarray(joints["position"])[:, 0]
    tip = np.column_stack([np.asarray(fields[f"pose.position.{a}"]) for a in "xyz"])
    level = np.einsum("nij,nj->ni", level_rotation(base_up(up_cab, theta1)), tip)
    level[10:15, 2] += 2e-3
    values = {
        **{k: np.asarray(v) for k, v in fields.items() if k != "header.frame_id"},
        "header.frame_id": "base_level",
        **{f"pose.position.{a}": level[:, i] for i, a in enumerate("xyz")},
    }
    raw = encode_messages(pose.msgtype, n, values)
    topics["/bucket_pose_level"] = Topic(pose.msgtype, pose.log_time, raw)
    write_bag(tmp_path / "bag", topics, overwrite=True)
    report, _ = evaluate_bag(BagReader(tmp_path / "bag"), Setup())
    (machine,) = [m for m in report["machines"] if m["kind"] == "excavator"]
    entry = machine["consistency"]["bucket_pose_level"]
    assert entry["matched"] == n
    assert entry["position_m"]["max"] == pytest.approx(2e-3, abs=1e-9)
    assert entry["position_m"]["rms"] == pytest.approx(2e-3 * math.sqrt(5 / n), abs=1e-9)


def test_simulated_readings_match_the_independent_generator():
    """imu.simulated_readings (used by the slope example) against this file's pin-based generator."""
    from excavator_kinematics.sensing.imu import simulated_readings

    for body in ("h_link", "bucket"):
        arm = ImuArm(EXC, imu_section(body))
        D, D_dot = states(30)
        q, omega, f = simulated_readings(arm, D, D_dot, (0.05, -0.04, 0.3))
        data = [readings(d, v, body, (0.05, -0.04, 0.3)) for d, v in zip(D, D_dot, strict=True)]
        expected = up_from_orientation(np.array([x[0] for x in data]))
        np.testing.assert_allclose(up_from_orientation(q), expected, atol=1e-12)
        np.testing.assert_allclose(omega, np.array([x[1] for x in data]), atol=1e-8)
        np.testing.assert_allclose(f, np.array([x[2] for x in data]), atol=1e-12)


def test_slope_example_writes_bag_and_png(tmp_path):
    """The example (item 4) end to end, short: the bag opens with the surface mesh and the three
    grade topics, the PNG is written, and the IMU estimate's height error is within 4 x the
    first-order bound of its noise."""
    from matplotlib.image import imread

    from excavator_kinematics.demo.slope_example import run
    from manipulator_kinematics.bag.reader import BagReader

    result = run(tmp_path, seconds=2.0, rate=50.0)
    assert result["samples"] == 101
    # Height noise: the tip moves by about r sigma_theta2 (r ~ 7 m, sigma_theta2 = sqrt(2) 0.05 deg).
    assert result["rms_m"] < 4 * 7.0 * math.sqrt(2) * math.radians(0.05)
    topics = BagReader(tmp_path / "bag").topics
    for name in (
        "/design_surface",
        "/grade/tip",
        "/grade/left",
        "/grade/right",
        "/imu/cab",
        "/cylinder_lengths",
    ):
        assert name in topics, sorted(topics)
    assert imread(tmp_path / "grade_heights.png").shape[1] > 500
    assert read_landxml(tmp_path / "ditch.xml").faces.shape == (50, 3)


def tf_tree(bag_path) -> tuple[dict, dict]:
    """The bag's transforms, decoded with rosbags (not the project's codec): static child ->
    (parent, 4x4) and, per header stamp (ns), dynamic child -> (parent, 4x4)."""
    from rosbags.typesys import Stores, get_typestore

    from manipulator_kinematics.bag.reader import BagReader

    store = get_typestore(Stores.ROS2_JAZZY)
    static: dict[str, tuple[str, np.ndarray]] = {}
    dynamic: dict[int, dict[str, tuple[str, np.ndarray]]] = {}
    for topic, _, raw in BagReader(bag_path).messages(["/tf", "/tf_static"]):
        for t in store.deserialize_cdr(raw, "tf2_msgs/msg/TFMessage").transforms:
            r, p = t.transform.rotation, t.transform.translation
            pose = np.eye(4)
            pose[:3, :3] = Rotation.from_quat([r.x, r.y, r.z, r.w]).as_matrix()
            pose[:3, 3] = [p.x, p.y, p.z]
            stamp = t.header.stamp.sec * 1_000_000_000 + t.header.stamp.nanosec
            target = static if topic == "/tf_static" else dynamic.setdefault(stamp, {})
            target[t.child_frame_id] = (t.header.frame_id, pose)
    return static, dynamic


def compose(frame: str, edges: dict[str, tuple[str, np.ndarray]]) -> tuple[list[str], np.ndarray]:
    """The chain from ``frame`` up to the root (frames, child first) and root -> frame."""
    chain, pose = [frame], np.eye(4)
    while frame in edges:
        frame, step = edges[frame]
        pose = step @ pose
        chain.append(frame)
        assert len(chain) < 100, chain
    return chain, pose


def test_slope_example_bag_is_one_tf_tree(tmp_path):
    """Gap b: the example's bag composes site -> base_level -> base_link -> URDF links; the bucket
    tip through the tree is bucket_pose_site (the estimate placed by the cab IMU's tilt) to 1e-6 m,
    and base_level -> base_link is the level rotation of machine_tilt."""
    from rosbags.typesys import Stores, get_typestore

    from excavator_kinematics.demo.slope_example import run
    from manipulator_kinematics.bag.reader import BagReader
    from manipulator_kinematics.bag.visual import urdf_joints
    from manipulator_kinematics.registry import machine

    run(tmp_path, seconds=1.0, rate=20.0)
    bag = tmp_path / "bag"
    static, dynamic = tf_tree(bag)
    store = get_typestore(Stores.ROS2_JAZZY)
    poses = [
        store.deserialize_cdr(raw, "geometry_msgs/msg/PoseStamped")
        for _, _, raw in BagReader(bag).messages(["/bucket_pose_site"])
    ]
    tilts = [
        store.deserialize_cdr(raw, "geometry_msgs/msg/Vector3Stamped")
        for _, _, raw in BagReader(bag).messages(["/machine_tilt"])
    ]
    joints = {
        m.header.stamp.sec * 10**9 + m.header.stamp.nanosec: m.position[0]
        for _, _, m in (
            (t, x, store.deserialize_cdr(raw, "sensor_msgs/msg/JointState"))
            for t, x, raw in BagReader(bag).messages(["/joint_states"])
        )
    }
    assert len(poses) == len(tilts) == 21
    links = {j.child for j in urdf_joints(machine("excavator").urdf(EXC))}
    for pose, tilt in zip(poses, tilts, strict=True):
        stamp = pose.header.stamp.sec * 10**9 + pose.header.stamp.nanosec
        assert pose.header.frame_id == "site"
        edges = {**static, **dynamic[stamp]}
        chain, tip = compose("bucket_tip", edges)
        assert chain[-4:] == ["upper_structure", "base_link", "base_level", "site"], chain
        assert "bucket" in chain
        assert {compose(link, edges)[0][-1] for link in links} == {"site"}
        p = pose.pose.position
        np.testing.assert_allclose(tip[:3, 3], [p.x, p.y, p.z], rtol=0, atol=1e-6)
        o = pose.pose.orientation
        np.testing.assert_allclose(
            Rotation.from_matrix(tip[:3, :3]).as_quat(canonical=True),
            Rotation.from_quat([o.x, o.y, o.z, o.w]).as_quat(canonical=True),
            atol=1e-9,
        )
        # base_level -> base_link: world up in base_link is the tilt turned by the swing, and
        # base_level's z is that up (independent of level_rotation: the third row of R^T).
        parent, level = dynamic[stamp]["base_link"]
        assert parent == "base_level"
        up = Rotation.from_euler("z", joints[stamp]).apply([tilt.vector.x, tilt.vector.y, tilt.vector.z])
        np.testing.assert_allclose(level[:3, :3].T @ [0.0, 0.0, 1.0], up, atol=1e-12)
        # ...and base_level keeps base_link's heading: base_link's x has no y part in base_level.
        assert abs(level[1, 0]) < 1e-12 and level[0, 0] > 0


def test_bag_visuals_write_the_level_frame_from_machine_tilt(tmp_path):
    """Gap b, the visual writer alone: a recorded excavator bag with machine_tilt (a pitched and
    rolled machine, the cab swung) gets base_level -> base_link equal to the machine's known roll
    and pitch; without machine_tilt, no level frame."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Vector3, Vector3Stamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Header

    from excavator_kinematics.core.kinematics import CYLINDERS, JOINTS
    from manipulator_kinematics.bag.synthetic import Topic, write_bag
    from manipulator_kinematics.bag.visual import add_visuals
    from manipulator_kinematics.codec.packed import serialize_unpadded

    roll, pitch, swing = 0.04, -0.07, 0.8
    tilted = Rotation.from_euler("xyz", [roll, pitch, 0.0])  # base_link in a level frame
    up_upper = (Rotation.from_euler("z", swing).inv() * tilted.inv()).apply([0.0, 0.0, 1.0])
    stamps = np.array([1_000_000_000 + k * 10_000_000 for k in range(5)], dtype=np.int64)
    D = LIM.reference

    def header(s: int, frame: str = "") -> Header:
        return Header(stamp=Time(sec=int(s // 10**9), nanosec=int(s % 10**9)), frame_id=frame)

    def topics(with_tilt: bool) -> dict[str, Topic]:
        out = {
            "/joint_states": [
                JointState(header=header(s), name=[JOINTS[0]], position=[swing]) for s in stamps
            ],
            "/cylinder_lengths": [
                JointState(header=header(s), name=list(CYLINDERS), position=D[1:].tolist()) for s in stamps
            ],
        }
        if with_tilt:  # from the third state on: the first two have no level frame
            x, y, z = up_upper.tolist()
            out["/machine_tilt"] = [
                Vector3Stamped(header=header(s, "upper_structure"), vector=Vector3(x=x, y=y, z=z))
                for s in stamps[2:]
            ]
        kinds = {"/machine_tilt": "geometry_msgs/msg/Vector3Stamped"}
        return {
            name: Topic(
                kinds.get(name, "sensor_msgs/msg/JointState"),
                np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in msgs]),
                [serialize_unpadded(m) for m in msgs],
            )
            for name, msgs in out.items()
        }

    for with_tilt in (True, False):
        source, output = tmp_path / f"rec{with_tilt}", tmp_path / f"vis{with_tilt}"
        write_bag(source, topics(with_tilt))
        add_visuals(source, output)
        static, dynamic = tf_tree(output)
        levels = {s: edges["base_link"] for s, edges in dynamic.items() if "base_link" in edges}
        if not with_tilt:
            assert not levels
            continue
        assert sorted(levels) == stamps[2:].tolist()
        for parent, pose in levels.values():
            assert parent == "base_level"
            np.testing.assert_allclose(pose[:3, :3], tilted.as_matrix(), atol=1e-12)
            np.testing.assert_allclose(pose[:3, 3], 0.0, atol=0)
        assert compose("bucket_tip", {**static, **dynamic[int(stamps[3])]})[0][-1] == "base_level"


def test_mounting_figure_is_drawn(tmp_path):
    from matplotlib.image import imread

    from excavator_kinematics.sensing.imu_figure import draw

    draw(EXC, tmp_path / "frames.png")
    assert imread(tmp_path / "frames.png").shape[1] > 500
