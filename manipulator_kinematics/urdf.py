"""URDF descriptions of the registered machines, generated from their config (``mk_urdf``).

numpy only, no rclpy. A machine declares ``urdf=`` on its :class:`~manipulator_kinematics.registry.Machine`
(a function model -> URDF text); :func:`machine_urdf` calls it and the console script ``mk_urdf``
writes ``<machine>.urdf`` files (the shipped ones, generated from the shipped configs, are in
``urdf/`` and installed to ``share/manipulator_kinematics/urdf/``).

Serial D-H machines share :func:`serial_urdf`. Row i of a D-H chain is A_i = P_i M_i(w_i) K_i:
M_i the motion (Rz(w) for a revolute, Tz(w) for a prismatic row), K_i and P_i constants
(standard D-H: P_i = I, K_i = Tz(d) Tx(a) Rx(alpha) for a revolute row, Rz(theta) Tx(a)
Rx(alpha) for a prismatic one; modified D-H: P_i = Rx(alpha) Tx(a), K_i = Tz(d) resp.
Rz(theta)). URDF link i is the body frame right after M_i, on the joint axis; its joint's origin
is the constant transform from link i-1 to link i at the model's zero (every offset, such as the
pump boom's 180 deg unfolding convention, is folded into it) and its axis is z. The model's joint
values q map to the rows' variables by an affine map (the model's own, e.g. the palletizer's axis
angles -> D-H angles, times the chain's coupling matrix), so row i moves by sum_j K_ij q_j:

* the joint q_j sits on a row with K_ij = +-1 (axis +-z), as a ``revolute``/``prismatic`` joint
  named as the model names it, with the model's limits;
* every other term of a row is a ``mimic`` joint (``multiplier`` K_ij) in series on the same
  axis, with a massless link between: URDF's mimic follows one joint only, but rotations about
  (translations along) one axis add, so a sum such as the palletizer's passive flange joint
  theta4 = -(theta2 + theta3) is two mimic joints.

The model's frames (``model.frames(q)``: base, every D-H frame, tool last) are fixed child links
``frame_0`` ... ``frame_n`` and ``tool`` of the links they ride on, so a URDF user's tf tree holds
exactly the frames the package computes (test/test_urdf.py checks this with Pinocchio's URDF
parser at random states). Visuals are cylinders from each link to the next joint, for RViz and
Foxglove; no inertias (robot_state_publisher needs none).
"""

from __future__ import annotations

import argparse
import math
import sys
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from manipulator_kinematics.help_text import plain
from manipulator_kinematics.param_files import ConfigError
from manipulator_kinematics.registry import machine as find
from manipulator_kinematics.registry import machines
from manipulator_kinematics.serial_chain import JointLimits, SerialChain, transl, trotx, trotz

#: Colours of the visuals (RGBA).
MATERIALS = {
    "structure": (0.93, 0.71, 0.13, 1.0),  # machine yellow
    "steel": (0.35, 0.35, 0.38, 1.0),
    "chrome": (0.85, 0.85, 0.88, 1.0),
    "pin": (0.15, 0.15, 0.15, 1.0),
}
# Entries this close to zero are written as 0 (no -0.0 or 1e-17 round-off in committed files).
_ZERO = 1e-15
# Numbers are written with 15 significant digits (DBL_DIG: every such decimal survives the trip
# to a double and back, so a config's 0.6545196915 comes out as typed): repr's 17 digits would
# show the last bit of a computed value, which differs between CPUs (numpy's SIMD paths), and
# make the shipped files depend on the machine they were made on. 15 digits keep every value
# of these machines (|x| < 100 m) to 1e-13, far below what a URDF user can see.
PRECISION = 15


def machine_urdf(machine_name: str, model: Any = None) -> str:
    """The URDF (XML text) of a registered machine: ``model`` (default: the shipped config's).

    Raises KeyError for an unknown machine and LookupError for one without a ``urdf`` hook.
    """
    machine = find(machine_name)
    if machine.urdf is None:
        raise LookupError(f"machine {machine_name!r} declares no urdf hook")
    return machine.urdf(machine.model() if model is None else model)


# ---------------------------------------------------------------------------------------------- XML
def _number(value: float) -> str:
    value = float(value)
    return "0" if abs(value) < _ZERO else f"{value:.{PRECISION}g}"


def _numbers(values: ArrayLike) -> str:
    return " ".join(_number(v) for v in np.asarray(values, dtype=float).ravel())


def rpy(rotation: ArrayLike) -> np.ndarray:
    """URDF roll, pitch, yaw (R = Rz(yaw) Ry(pitch) Rx(roll)) of a rotation matrix.

    The pitch comes from atan2 (not asin) so it is accurate near +-90 deg; the result is checked
    to reproduce the matrix to 1e-12, which fails loudly instead of writing a wrong origin.
    """
    r = np.asarray(rotation, dtype=float)
    pitch = math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0]))
    if math.hypot(r[0, 0], r[1, 0]) > 1e-9:
        roll, yaw = math.atan2(r[2, 1], r[2, 2]), math.atan2(r[1, 0], r[0, 0])
    else:  # gimbal lock: only roll - yaw (pitch +90) or roll + yaw (pitch -90) is defined
        roll, yaw = math.atan2(-r[1, 2], r[1, 1]), 0.0
        pitch = math.copysign(math.pi / 2, pitch)
    angles = np.array([roll, pitch, yaw])
    back = rotation_rpy(angles)
    if not np.allclose(back, r, atol=1e-12, rtol=0.0):
        raise ValueError(f"rpy of {r.tolist()} does not reproduce it")
    return angles


def rotation_rpy(angles: ArrayLike) -> np.ndarray:
    """Rz(yaw) Ry(pitch) Rx(roll) (3, 3): URDF's origin rotation."""
    roll, pitch, yaw = np.asarray(angles, dtype=float)
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll),
        math.sin(roll),
        math.cos(pitch),
        math.sin(pitch),
        math.cos(yaw),
        math.sin(yaw),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _z_towards(direction: np.ndarray) -> np.ndarray:
    """A rotation whose z axis is ``direction`` (unit): the orientation of a URDF cylinder."""
    z = direction / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


class Robot:
    """A URDF document under construction: links, joints and their visuals, in insertion order."""

    def __init__(self, name: str, comment: str = "") -> None:
        self.root = ET.Element("robot", name=name)
        if comment:
            self.root.append(ET.Comment(f" {comment} "))
        for material, rgba in MATERIALS.items():
            ET.SubElement(ET.SubElement(self.root, "material", name=material), "color", rgba=_numbers(rgba))
        self._links: dict[str, ET.Element] = {}
        self.joints: list[str] = []

    def link(self, name: str) -> ET.Element:
        if name in self._links:
            raise ValueError(f"link {name!r} defined twice")
        self._links[name] = ET.SubElement(self.root, "link", name=name)
        return self._links[name]

    def joint(
        self,
        name: str,
        kind: str,
        parent: str,
        child: str,
        origin: ArrayLike | None = None,
        *,
        axis: ArrayLike | None = None,
        limits: tuple[float, float] | None = None,
        mimic: tuple[str, float] | None = None,
    ) -> None:
        """A joint; ``origin`` the 4x4 transform parent -> joint frame (default identity)."""
        if name in self.joints:
            raise ValueError(f"joint {name!r} defined twice")
        self.joints.append(name)
        element = ET.SubElement(self.root, "joint", name=name, type=kind)
        ET.SubElement(element, "parent", link=parent)
        ET.SubElement(element, "child", link=child)
        _origin(element, np.eye(4) if origin is None else origin)
        if axis is not None:
            ET.SubElement(element, "axis", xyz=_numbers(axis))
        if limits is not None:
            # URDF requires effort and velocity; 0 = not modelled (robot_state_publisher ignores them).
            ET.SubElement(
                element, "limit", lower=_number(limits[0]), upper=_number(limits[1]), effort="0", velocity="0"
            )
        if mimic is not None:
            ET.SubElement(element, "mimic", joint=mimic[0], multiplier=_number(mimic[1]), offset="0")

    def fixed(self, name: str, parent: str, origin: ArrayLike) -> None:
        """A fixed frame ``name`` on link ``parent`` (its joint is ``<name>_fixed``)."""
        self.link(name)
        self.joint(f"{name}_fixed", "fixed", parent, name, origin)

    def segment(self, link: str, start: ArrayLike, end: ArrayLike, radius: float, material: str) -> None:
        """A cylinder visual of ``link`` from ``start`` to ``end`` (link coordinates, m)."""
        start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
        length = float(np.linalg.norm(end - start))
        if length < 1e-9:
            return
        pose = np.eye(4)
        pose[:3, :3] = _z_towards(end - start)
        pose[:3, 3] = 0.5 * (start + end)
        visual = ET.SubElement(self._links[link], "visual")
        _origin(visual, pose)
        geometry = ET.SubElement(visual, "geometry")
        ET.SubElement(geometry, "cylinder", radius=_number(radius), length=_number(length))
        ET.SubElement(visual, "material", name=material)

    def sphere(self, link: str, centre: ArrayLike, radius: float, material: str) -> None:
        visual = ET.SubElement(self._links[link], "visual")
        _origin(visual, transl(*np.asarray(centre, dtype=float)))
        ET.SubElement(ET.SubElement(visual, "geometry"), "sphere", radius=_number(radius))
        ET.SubElement(visual, "material", name=material)

    def xml(self) -> str:
        tree = ET.ElementTree(self.root)
        ET.indent(tree, space="  ")
        return '<?xml version="1.0"?>\n' + ET.tostring(self.root, encoding="unicode") + "\n"


def _origin(element: ET.Element, transform: ArrayLike) -> None:
    t = np.asarray(transform, dtype=float)
    ET.SubElement(element, "origin", xyz=_numbers(t[:3, 3]), rpy=_numbers(rpy(t[:3, :3])))


# ---------------------------------------------------------------------------------------- serial
def affine_map(function: Callable[[np.ndarray], np.ndarray], n: int) -> tuple[np.ndarray, np.ndarray]:
    """(A, b) with function(q) = A q + b, from n + 1 evaluations; ValueError unless affine."""
    b = np.asarray(function(np.zeros(n)), dtype=float)
    A = np.stack([np.asarray(function(e), dtype=float) - b for e in np.eye(n)], axis=-1)
    probe = np.linspace(-1.3, 0.7, n)  # any point: an affine map agrees there too
    if not np.allclose(function(probe), A @ probe + b, atol=1e-12, rtol=0.0):
        raise ValueError(
            "the map from the model's joints to the chain's is not affine: no URDF joint can follow it"
        )
    return A, b


def _row_parts(row: Any, modified: bool, w: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """P_i, M_i(w), K_i of a D-H row (module docstring) at row value w (offset included)."""
    if row.prismatic:
        motion, rest = transl(0.0, 0.0, w), trotz(row.theta)
    else:
        motion, rest = trotz(w), transl(0.0, 0.0, row.d)
    if modified:
        return trotx(row.alpha) @ transl(row.a, 0.0, 0.0), motion, rest
    return np.eye(4), motion, rest @ transl(row.a, 0.0, 0.0) @ trotx(row.alpha)


def serial_urdf(
    name: str,
    model: Any,
    *,
    to_chain: Callable[[np.ndarray], np.ndarray] | None = None,
    limits: JointLimits | None = None,
) -> str:
    """URDF of a serial D-H machine (module docstring) from ``model.chain`` and ``model.frames``.

    ``to_chain`` maps the model's joint values (n,) to the chain's (affine; default identity);
    ``limits`` default ``model.limits`` (their names are the URDF's actuated joints).
    """
    chain: SerialChain = model.chain
    limits = model.limits if limits is None else limits
    names, n = tuple(limits.names), len(limits.names)
    A, b = affine_map(to_chain or (lambda q: q), n)
    if A.shape[0] != chain.n:
        raise ValueError(f"the model has {n} joints but its chain takes {chain.n}")
    K = chain.coupling @ A  # row variable i moves by sum_j K_ij q_j
    w0 = chain.coupling @ b + np.array([r.offset for r in chain.rows])  # row values at q = 0
    owners = _owners(K, names)

    # Link frames J_i at q = 0 (after M_i) and the D-H frames G_i (checked against the chain).
    J, G = [np.eye(4)], [chain.base]
    for row, w in zip(chain.rows, w0, strict=True):
        pre, motion, rest = _row_parts(row, chain.modified, float(w))
        J.append(G[-1] @ pre @ motion)
        G.append(J[-1] @ rest)
    expected = chain.fkine(A @ np.zeros(n) + b, all_frames=True)
    if not np.allclose(np.stack(G), expected, atol=1e-12):
        raise ValueError("D-H rows and SerialChain disagree (unsupported row form)")
    frames = np.asarray(model.frames(np.zeros(n)), dtype=float)
    if frames.shape[0] not in (chain.n_rows + 1, chain.n_rows + 2):
        raise ValueError(f"model.frames gives {frames.shape[0]} frames for {chain.n_rows} rows")

    lengths = [np.linalg.norm(J[i + 1][:3, 3] - J[i][:3, 3]) for i in range(chain.n_rows)]
    radius = 0.02 * max(sum(lengths), 1e-3)
    robot = Robot(name, f"generated by mk_urdf from the {name} config: do not edit")
    robot.link("base_link")
    parent = "base_link"
    for i, row in enumerate(chain.rows, start=1):
        kind = "prismatic" if row.prismatic else "revolute"
        steps: list[tuple[str, str, dict[str, Any]]] = []
        for j in np.flatnonzero(K[i - 1]):
            k = float(K[i - 1, j])
            if owners[j] == i:  # the joint itself: its value is q_j, along +-z
                steps.append(
                    (
                        names[j],
                        kind,
                        {
                            "axis": (0.0, 0.0, math.copysign(1.0, k)),
                            "limits": (limits.lower[j], limits.upper[j]),
                        },
                    )
                )
            else:
                span = sorted((k * limits.lower[j], k * limits.upper[j]))
                steps.append(
                    (
                        f"link_{i}_mimic_{names[j]}",
                        kind,
                        {"axis": (0.0, 0.0, 1.0), "limits": tuple(span), "mimic": (names[j], k)},
                    )
                )
        if not steps:
            steps.append((f"link_{i}_fixed", "fixed", {}))
        origin = np.linalg.solve(J[i - 1], J[i])
        robot.segment(parent, np.zeros(3), origin[:3, 3], radius, "structure")
        for k, (joint, joint_kind, options) in enumerate(steps, start=1):
            child = f"link_{i}" if k == len(steps) else f"link_{i}_part_{k}"
            robot.link(child)
            robot.joint(joint, joint_kind, parent, child, origin, **options)
            origin, parent = None, child
        robot.sphere(parent, np.zeros(3), 1.5 * radius, "pin")
    robot.fixed("frame_0", "base_link", frames[0])
    for i in range(1, chain.n_rows + 1):
        robot.fixed(f"frame_{i}", f"link_{i}", np.linalg.solve(J[i], frames[i]))
    tool = np.linalg.solve(J[-1], frames[-1])
    robot.segment(parent, np.zeros(3), tool[:3, 3], radius, "structure")
    robot.fixed("tool", parent, tool)
    return robot.xml()


def _owners(K: np.ndarray, names: Sequence[str]) -> dict[int, int]:
    """Row (1-based) of each joint: the first free row it moves with coefficient +-1."""
    owners: dict[int, int] = {}
    for j, name in enumerate(names):
        rows = [
            i + 1
            for i in np.flatnonzero(np.isclose(np.abs(K[:, j]), 1.0, rtol=0.0, atol=1e-12))
            if i + 1 not in owners.values()
        ]
        if not rows:
            raise ValueError(f"joint {name} moves no D-H row one-to-one: it cannot be a URDF joint")
        owners[j] = rows[0]
    return owners


def prefixed_urdf(text: str, prefix: str) -> str:
    """The URDF with ``prefix`` before every link name (several machines in one tf tree)."""
    if not prefix:
        return text
    root = ET.fromstring(text)
    for link in root.iter("link"):
        link.set("name", prefix + link.get("name"))
    for joint in root.iter("joint"):
        for end in ("parent", "child"):
            element = joint.find(end)
            element.set("link", prefix + element.get("link"))
    return ET.tostring(root, encoding="unicode")


# ------------------------------------------------------------------------------------------- CLI
def main(argv: Sequence[str] | None = None) -> int:
    """``mk_urdf MACHINE [-o FILE] [--params-file FILE]`` or ``mk_urdf --all DIR``."""
    parser = argparse.ArgumentParser(prog="mk_urdf", description=plain(__doc__.splitlines()[0]))
    parser.add_argument("machine", nargs="?", help="registered machine name (omit with --all)")
    parser.add_argument("-o", "--output", type=Path, help="URDF file to write (default: standard output)")
    parser.add_argument(
        "--params-file", type=Path, help="ROS params file with the machine (default: the shipped one)"
    )
    parser.add_argument(
        "--frame-prefix",
        default="",
        metavar="PREFIX",
        help="put PREFIX before every link name (e.g. m1/: two machines in one TF tree; "
        "robot_state_publisher's frame_prefix does this for /tf itself)",
    )
    parser.add_argument(
        "--all",
        type=Path,
        metavar="DIR",
        help="write <machine>.urdf of every registered machine (shipped configs) into DIR",
    )
    args = parser.parse_args(argv)
    if (args.all is None) == (args.machine is None):
        parser.error("give a machine name or --all DIR")
    if args.all is not None and (args.output or args.params_file or args.frame_prefix):
        parser.error("--all writes the shipped configs' URDFs: no -o, --params-file or --frame-prefix")
    try:
        if args.all is not None:
            args.all.mkdir(parents=True, exist_ok=True)
            for name, machine in machines().items():
                if machine.urdf is not None:
                    path = args.all / f"{name}.urdf"
                    path.write_text(machine_urdf(name))
                    print(f"wrote {path}")
            return 0
        text = prefixed_urdf(
            machine_urdf(args.machine, find(args.machine).model(args.params_file)), args.frame_prefix
        )
    except (KeyError, LookupError, ConfigError, ValueError) as error:
        print(f"mk_urdf: {error}", file=sys.stderr)
        return 2
    if args.output is None:
        sys.stdout.write(text)
    else:
        args.output.parent.mkdir(parents=True, exist_ok=True)
        args.output.write_text(text)
        print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
