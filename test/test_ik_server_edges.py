"""solve_ik and solve_fk of every serial machine at the edges of float64: huge (1e300, the largest
double), tiny (1e-300), denormal (5e-324), inf and NaN in each coordinate, degenerate quaternions
(zero, 1e-10, one of denormals, 1e-160 whose square underflows, 1e308 whose norm overflows, inf,
NaN), and the same in seeds, joint states and velocities. Real servers over DDS.

Every answer is success with finite values, or success = false with the code of the rule
(KinematicsErrorCodes.msg) and a reason: a target or quaternion that is no goal is
INVALID_GOAL_CONSTRAINTS, a seed or joint state that is no state INVALID_ROBOT_STATE; a valid
but unreachable target a geometric code (NO_IK_SOLUTION, JOINT_LIMITS_VIOLATED, SINGULAR). Never
FAILURE and never "internal error".
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest
from ros_harness import IK_FK, Probe, runtime_warnings, start_with_services
from sensor_msgs.msg import JointState

from manipulator_kinematics.registry import machine
from manipulator_kinematics_interfaces.msg import KinematicsErrorCodes as Codes
from manipulator_kinematics_interfaces.srv import SolveFK, SolveIK

pytestmark = pytest.mark.ros

SERIAL = ("scara", "tool_changer", "palletizer", "pump_boom")
TIMEOUT = 30.0
MAX = 1.7976931348623157e308
HUGE = (1e300, -1e300, MAX, -MAX)
NOT_FINITE = (math.inf, -math.inf, math.nan)
# Valid numbers: the answer is a solution or a geometric failure, never an input error.
SMALL = (0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1e-300, -1e-20)
GEOMETRIC = {Codes.SUCCESS, Codes.NO_IK_SOLUTION, Codes.JOINT_LIMITS_VIOLATED, Codes.SINGULAR}
NOT_A_ROTATION = (
    (0.0, 0.0, 0.0, 0.0),
    (1e-10, 0.0, 0.0, 0.0),
    (5e-324, 5e-324, 0.0, 5e-324),
    (1e-160, 1e-160, 0.0, 0.0),
    (MAX, MAX, MAX, MAX),
    (0.0, 0.0, 0.0, math.inf),
    (math.nan, 0.0, 0.0, 1.0),
    (1.0, -math.inf, 0.0, 0.0),
)
# Not unit but rotations all the same (normalised): no input error.
SCALED = ((0.0, 0.0, 0.0, 2.0), (0.0, 0.0, 1e-9, 1e-9), (1e150, 0.0, 0.0, 1e150), (0.0, 0.0, 0.0, -1.0))


@pytest.fixture(scope="module", params=SERIAL)
def server(request: pytest.FixtureRequest, probe: Probe) -> Iterator[tuple[str, object, object]]:
    name = request.param
    process, (ik, fk) = start_with_services(probe, f"{name}_ik_server", services=IK_FK, timeout=TIMEOUT)
    try:
        yield name, ik, fk
    finally:
        log = process.stop()
        assert "Traceback" not in log and not runtime_warnings(log), log


def target(
    position,
    quaternion=(0.0, 0.0, 0.0, 1.0),
    *,
    use_orientation: bool = False,
    seed: JointState | None = None,
) -> SolveIK.Request:
    request = SolveIK.Request(use_orientation=use_orientation)
    p, o = request.target.pose.position, request.target.pose.orientation
    p.x, p.y, p.z = (float(v) for v in position)
    o.x, o.y, o.z, o.w = (float(v) for v in quaternion)
    if seed is not None:
        request.seed = seed
    return request


def answers(probe: Probe, client, requests: list) -> list:
    return [probe.call(client, r, TIMEOUT) for r in requests]


def check(responses: list, requests: list, codes: set[int], text: str = "") -> None:
    for request, response in zip(requests, responses, strict=True):
        what = (request, response.error_code.val, response.message[:300])
        assert response.error_code.val in codes, what
        assert response.success == (response.error_code.val == Codes.SUCCESS), what
        assert "internal error" not in response.message and len(response.message) < 2000, what
        if response.success:
            fields = (
                [*response.solution.position]
                if hasattr(response, "solution")
                else [
                    *(getattr(response.pose.pose.position, a) for a in "xyz"),
                    *(getattr(response.twist.twist.linear, a) for a in "xyz"),
                ]
            )
            assert fields and all(map(math.isfinite, fields)), what
        else:
            assert text in response.message and response.message, what


def test_targets_at_the_edges_of_float64(probe: Probe, server) -> None:
    name, ik, _ = server
    home = machine(name).model().fkine(_inside(name))[:3, 3]
    for axis in range(3):
        for values, codes, text in (
            (HUGE, {Codes.INVALID_GOAL_CONSTRAINTS}, "implausible"),
            (NOT_FINITE, {Codes.INVALID_GOAL_CONSTRAINTS}, "not finite"),
            (SMALL, GEOMETRIC, ""),
        ):
            requests = []
            for value in values:
                position = home.copy()
                position[axis] = value
                requests.append(target(position))
            check(answers(probe, ik, requests), requests, codes, text)


def test_quaternions_that_are_no_rotation(probe: Probe, server) -> None:
    name, ik, _ = server
    home = machine(name).model().fkine(_inside(name))
    requests = [target(home[:3, 3], q, use_orientation=True) for q in NOT_A_ROTATION]
    if name == "pump_boom":  # position only: any orientation asked for is refused
        check(answers(probe, ik, requests), requests, {Codes.INVALID_GOAL_CONSTRAINTS})
        return
    check(answers(probe, ik, requests), requests, {Codes.INVALID_GOAL_CONSTRAINTS}, "not a rotation")
    scaled = [target(home[:3, 3], q, use_orientation=True) for q in SCALED]
    check(answers(probe, ik, scaled), scaled, GEOMETRIC)
    # Without use_orientation the quaternion is not read at all.
    ignored = [target(home[:3, 3], q) for q in NOT_A_ROTATION]
    check(answers(probe, ik, ignored), ignored, GEOMETRIC)


def test_seeds_and_joint_states_at_the_edges_of_float64(probe: Probe, server) -> None:
    name, ik, fk = server
    record = machine(name)
    model = record.model()
    names = list(record.limits(model).names)
    inside = _inside(name)
    home = model.fkine(inside)[:3, 3]
    for values, seed_codes, fk_codes in (
        (NOT_FINITE, {Codes.INVALID_ROBOT_STATE}, {Codes.INVALID_ROBOT_STATE}),
        (HUGE, {Codes.INVALID_ROBOT_STATE}, {Codes.JOINT_LIMITS_VIOLATED}),
        (SMALL, GEOMETRIC, {Codes.SUCCESS, Codes.JOINT_LIMITS_VIOLATED}),
    ):
        seeds, states, rates = [], [], []
        for value in values:
            for j in range(len(names)):
                q = inside.copy()
                q[j] = value
                seeds.append(target(home, seed=JointState(name=names, position=q.tolist())))
                states.append(SolveFK.Request(joint_state=JointState(name=names, position=q.tolist())))
                rates.append(
                    SolveFK.Request(
                        joint_state=JointState(
                            name=names, position=inside.tolist(), velocity=[value] * len(names)
                        )
                    )
                )
        check(answers(probe, ik, seeds), seeds, seed_codes)
        check(answers(probe, fk, states), states, fk_codes)
        # A non-finite rate is no state; a huge one is refused where the twist overflows (finite
        # twists are answered: there are no rate limits); a tiny one is a twist.
        rate_codes = (
            {Codes.INVALID_ROBOT_STATE}
            if values is NOT_FINITE
            else ({Codes.SUCCESS} if values is SMALL else {Codes.SUCCESS, Codes.INVALID_ROBOT_STATE})
        )
        check(answers(probe, fk, rates), rates, rate_codes)


def _inside(name: str) -> np.ndarray:
    """A state well inside the limits (their midpoint), as joint values of the services."""
    limits = machine(name).limits(machine(name).model())
    return (np.asarray(limits.lower) + np.asarray(limits.upper)) / 2


def test_a_dropped_response_is_no_runtime_warning_of_the_node() -> None:
    """The filter of the servers' logs above keeps numpy's warnings and leaves out only rclpy's
    dropped response (a CI run's log: DDS discovery, answered by ``Probe.call`` re-sending)."""
    dropped = (
        "/venv/lib/python3.11/site-packages/rclpy/service.py:78: RuntimeWarning: failed to send "
        "response (timeout): client will not receive response, at /project/src/rmw_response.cpp:153\n"
        "  self.__service.service_send_response(response, header.request_id)\n"
    )
    overflow = "/src/scara_kinematics/core.py:80: RuntimeWarning: overflow encountered in multiply\n"
    assert runtime_warnings(dropped) == []
    assert runtime_warnings(dropped + overflow) == [overflow.strip()]
