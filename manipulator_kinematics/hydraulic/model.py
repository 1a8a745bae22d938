"""One numpy core for every machine of the hydraulic family (paper 000, eqs. 1-13).

:class:`HydraulicModel` solves a :class:`~manipulator_kinematics.hydraulic.description.Description`
by its plan: dyads in order (:mod:`manipulator_kinematics.hydraulic.dyads`), each body placed from
two known pins, each prismatic child slid along its parent. Every pin is carried as a jet: its
position, its Jacobian d/dD (closed form, the dyads differentiated implicitly) and, along a motion
(Ddot, Dddot), its velocity and acceleration. From the jets: the main-chain joints theta, K =
dtheta/dD (eq. 7, not diagonal where a linkage spans two joints, as the loader's Z-bar), the task
vector Q (eq. 3), JC0 = dQ/dD (eq. 8), Qdot and Qddot (eqs. 10-11); J0 = dQ/dtheta (eqs. 4-5) in
closed form from the open chain, so that J0 K = JC0 is a check. The inverses: cylinder rates from
a target task rate (eq. 9), cylinder accelerations (eqs. 12-13), position IK (:meth:`ik`).

Arrays: D (..., m) with m = len(actuator_names) (the swing angle first if the machine swings),
theta (..., n) (theta1 first if it swings), Q (..., 4) = [x, y, z, alpha] or (..., 3) = [x, y, z].
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from manipulator_kinematics.compiled import Kernel
from manipulator_kinematics.hydraulic import dyads, layout
from manipulator_kinematics.hydraulic.description import SECTION, Description, Dyad, Place, Slide, read
from manipulator_kinematics.hydraulic.program import Monitored, Program, pack, pack_monitored
from manipulator_kinematics.param_files import ConfigError

__all__ = ["HydraulicModel", "HydraulicState", "IKResult", "RateSolution", "StrokeError", "compiled_kernel"]


def _warm(kernel: ModuleType) -> None:
    """Refuse a kernel compiled for another layout, run each function once (numba loads or
    compiles it; a one-actuator program that refuses its state), then let it take only those
    types: arguments of others (a list, a strided view, integers) raise TypeError and the caller
    takes the numpy path instead of compiling for seconds in a call."""
    layout.check_compiled(kernel)
    code = np.zeros((2, len(layout.INT)), dtype=np.int64)
    code[0, layout.INT.op], code[1, layout.INT.op] = layout.OP.head, layout.OP.limit
    code[0, layout.INT.act2] = 1
    values = np.zeros((2, len(layout.FLOAT)))
    values[1, layout.FLOAT.x] = 1.0  # the box [1, 0]: no state is inside
    D, batch = np.zeros(1), np.zeros((1, 1))
    kernel.state(code, values, D, D, D, np.empty((1, 4)))
    kernel.pose(code, values, D, np.empty(1))
    kernel.jc0(code, values, D, np.empty((1, 1)))
    kernel.states(code, values, batch, batch, batch, np.empty((1, 1, 4)))
    kernel.poses(code, values, batch, np.empty((1, 1)))
    kernel.jc0s(code, values, batch, np.empty((1, 1, 1)))
    out = np.empty((1, 3))
    kernel.monitored(
        code, values, np.zeros((1, len(layout.POINT)), dtype=np.int64), 0.5, 0, D, D, out, out, out
    )
    for function in (
        kernel.state,
        kernel.pose,
        kernel.jc0,
        kernel.states,
        kernel.poses,
        kernel.jc0s,
        kernel.monitored,
    ):
        function.disable_compile()


#: The single-state kernel of every family machine (:mod:`manipulator_kinematics.hydraulic.kernel`),
#: loaded in the background by the first single call (manipulator_kinematics.compiled).
KERNEL = Kernel("manipulator_kinematics.hydraulic.kernel", _warm)


def compiled_kernel(wait: bool = False) -> ModuleType | None:
    """The compiled kernel module if ready, else None (the first single call starts loading it;
    calls take the numpy path meanwhile, the same results within 1e-12). ``wait``: load it now."""
    return KERNEL.get(wait=wait)


class StrokeError(ValueError):
    """A state outside the stroke box, or one the linkage cannot take; the message names the actuator."""


@dataclass
class _Jet:
    """A value with its Jacobian d/dD (one more axis of length m before the value's own), its
    velocity and its acceleration along the motion (Ddot, Dddot)."""

    p: np.ndarray
    J: np.ndarray
    v: np.ndarray
    a: np.ndarray


def _rot(phi: np.ndarray, local: np.ndarray) -> np.ndarray:
    c, s = np.cos(phi), np.sin(phi)
    return np.stack((c * local[..., 0] - s * local[..., 1], s * local[..., 0] + c * local[..., 1]), axis=-1)


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Angle wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - angle, 2.0 * np.pi)


class _Body:
    """A placed body: origin jet (points) and angle jet (scalars)."""

    def __init__(self, origin: _Jet, angle: _Jet) -> None:
        self.origin, self.angle = origin, angle

    def point(self, local: np.ndarray) -> _Jet:
        """The jet of the point ``local`` of this body: P = O + R(phi) l."""
        o, f = self.origin, self.angle
        w = _rot(f.p, np.broadcast_to(local, o.p.shape))
        n = dyads.perp(w)
        return _Jet(
            o.p + w,
            o.J + f.J[..., None] * n[..., None, :],
            o.v + f.v[..., None] * n,
            o.a + f.a[..., None] * n - (f.v * f.v)[..., None] * w,
        )


@dataclass
class _Solved:
    pins: dict[str, _Jet]
    bodies: dict[str, _Body]
    margins: np.ndarray  # (..., dyads) rad
    closure: np.ndarray  # (..., dyads) h^2 of each dyad (<= 0: it does not close)
    theta: _Jet
    Q: _Jet


def _field(i: int, doc: str) -> property:
    """Field ``i`` of :class:`HydraulicState` (``_FIELDS``): given, or a view of its table."""

    def get(self: HydraulicState) -> np.ndarray:
        if self._values is not None:
            return self._values[i]
        chain, column = _FIELDS[i]
        return self._table[..., : self._n, column] if chain else self._table[..., self._n :, column]

    return property(get, doc=doc)


# Per field of HydraulicState: theta's rows (else Q's) of the table, and the column(s): value,
# rate, acceleration, d/dD (the compiled kernel's result, kernel.state).
_FIELDS: tuple[tuple[bool, int | slice], ...] = (
    (True, 0),
    (True, 1),
    (True, 2),
    (False, 0),
    (False, 1),
    (False, 2),
    (False, slice(3, None)),
    (True, slice(3, None)),
)


class HydraulicState:
    """Forward kinematic state (paper eqs. 3, 7, 8, 10-11); leading axes those of D.

    Made from its eight arrays, or (:meth:`of_table`, the compiled single call) over one table
    (..., n + nq, 3 + m), theta's then Q's rows of (value, rate, acceleration, d/dD), its fields
    views made when read: making eight views costs about as much as the compiled call.
    """

    __slots__ = ("_n", "_table", "_values")
    _fields = ("theta", "theta_dot", "theta_ddot", "Q", "Q_dot", "Q_ddot", "jc0", "k")

    def __init__(
        self,
        theta: np.ndarray,
        theta_dot: np.ndarray,
        theta_ddot: np.ndarray,
        Q: np.ndarray,
        Q_dot: np.ndarray,
        Q_ddot: np.ndarray,
        jc0: np.ndarray,
        k: np.ndarray,
    ) -> None:
        self._values: tuple[np.ndarray, ...] | None = (theta, theta_dot, theta_ddot, Q, Q_dot, Q_ddot, jc0, k)
        self._table: np.ndarray = np.empty(0)
        self._n = 0

    @classmethod
    def of_table(cls, table: np.ndarray, n: int) -> HydraulicState:
        """The state over ``table`` (..., n + nq, 3 + m) (class docstring)."""
        state = cls.__new__(cls)
        state._values, state._table, state._n = None, table, n
        return state

    theta = _field(0, "(..., n) main-chain joints (rad; m for a prismatic joint)")
    theta_dot = _field(1, "(..., n) joint rates, K Ddot (eq. 7)")
    theta_ddot = _field(2, "(..., n) joint accelerations")
    Q = _field(3, "(..., nq) [x, y, z(, alpha)] (eq. 3)")
    Q_dot = _field(4, "(..., nq) task rates, JC0 Ddot (eq. 8)")
    Q_ddot = _field(5, "(..., nq) task accelerations (eqs. 10-11)")
    jc0 = _field(6, "(..., nq, m) JC0 = dQ/dD, rows in Q's order (eq. 8)")
    k = _field(7, "(..., n, m) K = dtheta/dD (eq. 7)")

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.theta, self.theta_dot, self.theta_ddot, self.Q, self.Q_dot, self.Q_ddot, self.jc0))

    def __repr__(self) -> str:
        return f"HydraulicState({', '.join(f'{name}={getattr(self, name)!r}' for name in self._fields)})"


@dataclass(frozen=True)
class RateSolution:
    """Result of eq. 9: the cylinder rates, the task rates they give and the condition number."""

    D_dot: np.ndarray  # (..., m)
    Q_dot: np.ndarray  # (..., nq) = JC0 D_dot: every row, the ones not commanded included
    condition: np.ndarray  # (...,) 2-norm condition number of the commanded rows of JC0 S


@dataclass(frozen=True)
class IKResult:
    """Position IK: D (..., m) and whether each is a state of the machine (inside the stroke box)."""

    D: np.ndarray
    valid: np.ndarray  # (...,) bool


class HydraulicModel:
    """The kinematics of one machine of the family (module docstring)."""

    def __init__(self, description: Description, *, check: bool = True) -> None:
        """The model of ``description``, refused (ConfigError naming the key) unless it assembles
        over its stroke box (:meth:`check`). ``check`` False: the caller checks first, then calls
        :meth:`check` (the excavator's Excavator, whose checks of the same linkage name its keys
        its own way)."""
        self.description = description
        d = description
        self.actuator_names = d.actuator_names
        self.joint_names = d.joint_names
        self.task_names = d.task_names
        self.lower, self.upper, self.reference = d.lower, d.upper, d.reference
        self.max_speed = d.max_speed
        self.zero_offset = d.zero_offset
        self.m = len(self.actuator_names)
        self.swing = d.swing is not None
        self._dyads = [s for s in d.steps if isinstance(s, Dyad)]
        self.dyad_names = tuple(s.pin for s in self._dyads)
        self._local = {pin: xz for pins in d.bodies.values() for pin, xz in pins.items()}
        self._placed_by = self._placing_dyads()
        # Constants of the solve, from the description alone: d/dD of each actuator, the pins a
        # later step reads (the rest are made only for pins() and friends).
        self._eye = np.eye(self.m)
        self._read = {p for s in self._dyads for p in (s.pivot, s.first)} | {
            p for s in d.steps if isinstance(s, Place) for p in (s.one, s.two)
        }
        #: The compiled kernel's program of this machine (manipulator_kinematics.hydraulic.program).
        self.program: Program = pack(d, self.lower, self.upper)
        # ... and what the single call reads of it and makes (one attribute lookup each).
        self._code, self._constants = self.program.code, self.program.values
        self._n, self._nq = self.program.n, self.program.nq
        self._table_shape = (self._n + self._nq, 3 + self.m)
        # A batch's outputs: (N, *shape) built of ints, that of a batch of one made once.
        self._table_rows, self._table_one = self._n + self._nq, (1, *self._table_shape)
        self._pose_shapes = (self._nq,), (1, self._nq)
        self._jc0_shapes = (self._nq, self.m), (1, self._nq, self.m)
        # D_ddot of a state without, and of every state of a batch (the kernel only reads it).
        self._no_acceleration, self._no_accelerations = np.zeros(self.m), np.zeros((1, self.m))
        #: The avoidance zones' monitored points as the kernel makes them (every velocity-IK command).
        self.monitored_points: Monitored = pack_monitored(d, self.lower, self.upper)
        if check:
            self.check()

    @classmethod
    def from_file(cls, path: str | Path, node_name: str = "/**") -> HydraulicModel:
        """The model of a family machine file (``hydraulic_machine`` section)."""
        return cls(read(path, node_name))

    # ------------------------------------------------------------------ checks
    def validate(self, D: Any) -> np.ndarray:
        """D as a float array (..., m), refused (StrokeError naming the actuator) outside the
        stroke box (faces included) or not finite."""
        D = np.asarray(D, dtype=float)
        if D.ndim == 0 or D.shape[-1] != self.m:
            raise StrokeError(
                f"D: expected (..., {self.m}) values [{', '.join(self.actuator_names)}], got shape {D.shape}"
            )
        if np.all((self.lower <= D) & (self.upper >= D)):  # NaN fails both: the loop names it
            return D
        for i, name in enumerate(self.actuator_names):
            column = D[..., i]
            bad = ~np.isfinite(column) | (column < self.lower[i]) | (column > self.upper[i])
            if np.any(bad):
                value = column[bad].flat[0]
                what = "is not finite" if not np.isfinite(value) else "is outside its stroke"
                raise StrokeError(
                    f"D[{i}] = {value:.6g} ({name}) {what} [{self.lower[i]:.6g}, {self.upper[i]:.6g}]"
                )
        return D

    def from_readings(self, readings: Any) -> np.ndarray:
        """D (..., m) from the actuators' sensor readings: true = reading + zero_offset (the
        machine file's, per actuator; strokes are true lengths), validated as :meth:`validate`."""
        readings = np.asarray(readings, dtype=float)
        if readings.ndim == 0 or readings.shape[-1] != self.m:
            raise StrokeError(
                f"readings: expected (..., {self.m}) values [{', '.join(self.actuator_names)}], "
                f"got shape {readings.shape}"
            )
        return self.validate(readings + self.zero_offset)

    def to_readings(self, D: Any) -> np.ndarray:
        """What the sensors read at the true state D: reading = D - zero_offset."""
        return self.validate(D) - self.zero_offset

    def _placing_dyads(self) -> dict[str, str]:
        """Body -> the dyad whose solution placed it (the last dyad before its Place step)."""
        out, last = {}, None
        for step in self.description.steps:
            if isinstance(step, Dyad):
                last = step.pin
            elif isinstance(step, Place) and last is not None:
                out[step.body] = last
            elif isinstance(step, Slide) and step.parent in out:
                out[step.child] = out[step.parent]
        return out

    def check(self) -> None:
        """Refuse a machine file whose linkage does not close, or leaves a joint's limits, over a
        5-point grid of every cylinder's stroke (swing at its reference): ConfigError naming the
        key (the constructor runs it unless told not to)."""
        axes = [np.linspace(lo, hi, 5) for lo, hi in zip(self.lower, self.upper, strict=True)]
        if self.swing:
            axes[0] = np.array([self.reference[0]])
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, self.m)
        states = np.concatenate((self.reference[None], grid))
        solved = self._solve(states)
        theta = solved.theta.p
        # In solve order: a dyad that does not close, then the joints its solution placed (a
        # wrong branch sign shows there first, before the dyads after it fail to close).
        for k, step in enumerate(self._dyads):
            open_ = ~(solved.closure[:, k] > 0.0)
            if np.any(open_):
                at = states[np.argmax(open_)]
                raise ConfigError(
                    f"{SECTION}.dyads.{step.pin}: does not close at "
                    f"D = {np.round(at, 6).tolist()} (inside the stroke box)"
                )
            for i, joint in enumerate(self.description.joints):
                if self._placed_by.get(joint.child) == step.pin:
                    blame = step.pin if joint.slide is None else None
                    self._check_limits(joint, theta[:, i + int(self.swing)], states, blame)
        for i, joint in enumerate(self.description.joints):  # the rest, and the prismatic joints
            self._check_limits(joint, theta[:, i + int(self.swing)], states, None)

    def _check_limits(self, joint: Any, values: np.ndarray, states: np.ndarray, dyad: str | None) -> None:
        out = (values < joint.lower) | (values > joint.upper)
        if not np.any(out):
            return
        k = int(np.argmax(out))
        where = "the reference state" if k == 0 else f"D = {np.round(states[k], 6).tolist()}"
        blame = out[0] and dyad is not None
        key = f"dyads.{dyad}.orientation" if blame else f"chain.{joint.name}.limits"
        hint = " (is the branch sign right?)" if blame else ""
        raise ConfigError(
            f"{SECTION}.{key}: {joint.name} = {np.degrees(values[k]):.3f} deg at {where}, "
            f"outside its limits [{np.degrees(joint.lower):.3f}, {np.degrees(joint.upper):.3f}] deg{hint}"
        )

    # ------------------------------------------------------------------ the solve
    def _solve(
        self,
        D: np.ndarray,
        D_dot: np.ndarray | None = None,
        D_ddot: np.ndarray | None = None,
        every_pin: bool = True,
    ) -> _Solved:
        """Every pin's jet for states D (..., m) (unchecked): the plan of dyads, placements and
        slides (eqs. 1-2 as dyads), then the main chain's joints and Q (eq. 3). ``every_pin``
        False: only the pins a later step reads (theta and Q the same, less work)."""
        shape = D.shape[:-1]
        m = self.m
        zero2, zeroJ2 = np.zeros(shape + (2,)), np.zeros(shape + (m, 2))
        zero, zeroJ = np.zeros(shape), np.zeros(shape + (m,))
        D_dot = np.zeros(D.shape) if D_dot is None else D_dot
        D_ddot = np.zeros(D.shape) if D_ddot is None else D_ddot
        eye = self._eye
        wanted = None if every_pin else self._read

        def actuator(i: int, offset: float = 0.0) -> _Jet:
            return _Jet(
                D[..., i] + offset, np.broadcast_to(eye[i], shape + (m,)), D_dot[..., i], D_ddot[..., i]
            )

        def radius(side: Any) -> _Jet:
            if side.index is None:
                return _Jet(np.full(shape, side.fixed), zeroJ, zero, zero)
            return actuator(side.index)

        d = self.description
        ground = _Body(_Jet(zero2, zeroJ2, zero2, zero2), _Jet(zero, zeroJ, zero, zero))
        bodies = {d.ground: ground}
        pins = {
            pin: ground.point(xz) for pin, xz in d.bodies[d.ground].items() if wanted is None or pin in wanted
        }
        margins, closure = [], []
        for step in d.steps:
            if isinstance(step, Dyad):
                a, b = pins[step.pivot], pins[step.first]
                ra, rb = radius(step.pivot_radius), radius(step.first_radius)
                x, h2 = dyads.intersect(a.p, b.p, ra.p, rb.p, step.orientation)
                J = dyads.rates(x, a.p, b.p, ra.p, rb.p, a.J, b.J, ra.J, rb.J)
                v = dyads.rates(x, a.p, b.p, ra.p, rb.p, a.v, b.v, ra.v, rb.v)
                acc = dyads.second_rates(
                    x, a.p, b.p, ra.p, rb.p, v, a.v, b.v, ra.v, rb.v, a.a, b.a, ra.a, rb.a
                )
                pins[step.pin] = _Jet(x, J, v, acc)
                margins.append(dyads.margin(x, a.p, b.p))
                closure.append(h2)
            elif isinstance(step, Place):
                body = self._place(
                    pins[step.one],
                    pins[step.two],
                    d.bodies[step.body][step.one],
                    d.bodies[step.body][step.two],
                )
                bodies[step.body] = body
                for pin, xz in d.bodies[step.body].items():
                    if pin not in pins and (wanted is None or pin in wanted):
                        pins[pin] = body.point(xz)
            else:
                body = self._slide(bodies[step.parent], step, actuator(step.index, step.offset))
                bodies[step.child] = body
                for pin, xz in d.bodies[step.child].items():
                    if pin not in pins and (wanted is None or pin in wanted):
                        pins[pin] = body.point(xz)
        theta = self._joints(bodies, D, actuator)
        tool = bodies[d.tool_body].point(d.bodies[d.tool_body][d.tool_pin])
        Q = self._task(tool, theta, actuator(0) if self.swing else None)
        return _Solved(pins, bodies, np.stack(margins, axis=-1), np.stack(closure, axis=-1), theta, Q)

    @staticmethod
    def _place(one: _Jet, two: _Jet, local_one: np.ndarray, local_two: np.ndarray) -> _Body:
        """The body through two known pins: phi = angle(P2 - P1) - angle(l2 - l1), O = P1 - R(phi) l1."""
        e = two.p - one.p
        eJ, ev, ea = two.J - one.J, two.v - one.v, two.a - one.a
        n2 = np.sum(e * e, axis=-1)
        dl = local_two - local_one
        phi = np.arctan2(e[..., 1], e[..., 0]) - np.arctan2(dl[1], dl[0])
        cross_v = dyads.cross(e, ev)
        angle = _Jet(
            phi,
            dyads.cross(e[..., None, :], eJ) / n2[..., None],
            cross_v / n2,
            dyads.cross(e, ea) / n2 - 2.0 * np.sum(e * ev, axis=-1) * cross_v / (n2 * n2),
        )
        w = _rot(phi, np.broadcast_to(local_one, e.shape))
        n = dyads.perp(w)
        origin = _Jet(
            one.p - w,
            one.J - angle.J[..., None] * n[..., None, :],
            one.v - angle.v[..., None] * n,
            one.a - angle.a[..., None] * n + (angle.v * angle.v)[..., None] * w,
        )
        return _Body(origin, angle)

    @staticmethod
    def _slide(parent: _Body, slide: Slide, s: _Jet) -> _Body:
        """The prismatic child: origin = O_p + R(phi_p) (axis_point + (s, 0)), parallel to the parent."""
        o, f = parent.origin, parent.angle
        axis = np.asarray(slide.axis_point, dtype=float)
        local = np.stack((axis[0] + s.p, np.full(s.p.shape, axis[1])), axis=-1)
        w = _rot(f.p, local)
        u = np.stack((np.cos(f.p), np.sin(f.p)), axis=-1)
        n, nu = dyads.perp(w), dyads.perp(u)
        origin = _Jet(
            o.p + w,
            o.J + f.J[..., None] * n[..., None, :] + s.J[..., None] * u[..., None, :],
            o.v + f.v[..., None] * n + s.v[..., None] * u,
            o.a
            + f.a[..., None] * n
            - (f.v * f.v)[..., None] * w
            + (2.0 * f.v * s.v)[..., None] * nu
            + s.a[..., None] * u,
        )
        return _Body(origin, f)

    def _joints(self, bodies: dict[str, _Body], D: np.ndarray, actuator: Any) -> _Jet:
        """theta (..., n): the swing, then theta_j = wrap(phi_child - phi_parent) or d_j = s."""
        parts = [actuator(0)] if self.swing else []
        for joint in self.description.joints:
            if joint.slide is not None:
                parts.append(actuator(joint.slide.index, joint.slide.offset))
                continue
            c, p = bodies[joint.child].angle, bodies[joint.parent].angle
            parts.append(_Jet(_wrap(c.p - p.p), c.J - p.J, c.v - p.v, c.a - p.a))
        return _Jet(*(np.stack([getattr(j, f) for j in parts], axis=-1 if f != "J" else -2) for f in "pJva"))

    def _revolute(self) -> list[int]:
        """Columns of theta that are revolute main-chain joints (alpha is their plain sum)."""
        return [i + int(self.swing) for i, j in enumerate(self.description.joints) if j.slide is None]

    def _task(self, tool: _Jet, theta: _Jet, swing: _Jet | None) -> _Jet:
        """Q = [x, y, z(, alpha)] (eq. 3): the boom-plane tool point (r, z) turned by the swing."""
        r, z = (
            _Jet(tool.p[..., 0], tool.J[..., 0], tool.v[..., 0], tool.a[..., 0]),
            _Jet(tool.p[..., 1], tool.J[..., 1], tool.v[..., 1], tool.a[..., 1]),
        )
        if swing is None:
            zero = _Jet(*(np.zeros_like(f) for f in (r.p, r.J, r.v, r.a)))
            x, y = r, zero
        else:
            c, s, w, e = np.cos(swing.p), np.sin(swing.p), swing.v, swing.a
            x = _Jet(
                r.p * c,
                r.J * c[..., None] - (r.p * s)[..., None] * swing.J,
                r.v * c - r.p * s * w,
                r.a * c - 2.0 * r.v * s * w - r.p * (c * w * w + s * e),
            )
            y = _Jet(
                r.p * s,
                r.J * s[..., None] + (r.p * c)[..., None] * swing.J,
                r.v * s + r.p * c * w,
                r.a * s + 2.0 * r.v * c * w + r.p * (c * e - s * w * w),
            )
        rows = [x, y, z]
        if self.description.has_angle:
            cols = self._revolute()
            rows.append(
                _Jet(
                    *(
                        np.sum(f[..., cols], axis=-1)
                        if f is not theta.J
                        else np.sum(f[..., cols, :], axis=-2)
                        for f in (theta.p, theta.J, theta.v, theta.a)
                    )
                )
            )
        return _Jet(*(np.stack([getattr(q, f) for q in rows], axis=-1 if f != "J" else -2) for f in "pJva"))

    # ------------------------------------------------------------------ forward API
    def _compiled(
        self, one: str, many: str, shapes: tuple[tuple[int, ...], tuple[int, ...]], D: np.ndarray
    ) -> np.ndarray | None:
        """The kernel's ``one`` (:mod:`manipulator_kinematics.hydraulic.kernel`) of one state D (m,),
        or its loop ``many`` over a batch D (N, m), into a new array (shape) or (N, *shape) (shapes:
        shape and that of a batch of one); None
        where the kernel is not loaded yet, cannot take D as given (another dtype or layout:
        :func:`_warm`) or refuses a state (the caller's numpy path then says why). A batch of one
        is the single call with one axis more (issue #32: it costs no more than the single call)."""
        kernel = KERNEL.ready or KERNEL.get()
        if kernel is None:
            return None
        try:
            ndim = D.ndim
            if ndim == 1:
                out = np.empty(shapes[0])
                return out if getattr(kernel, one)(self._code, self._constants, D, out) else None
            n = len(D)  # (N, m); other dimensions: TypeError in the kernel
            out = np.empty(shapes[1] if n == 1 else (n, *shapes[0]))
            return out if getattr(kernel, many)(self._code, self._constants, D, out) else None
        except TypeError:
            pass
        return None

    def _batch(self, function: str, shape: tuple[int, ...], D: np.ndarray, *motion: Any) -> np.ndarray | None:
        """The kernel's loop ``function`` over a batch D (..., m) the fast paths did not take (another
        dtype, layout or number of axes; D_dot, D_ddot of another shape, broadcast to D's; D_ddot
        None: zero): a table (..., *shape) of C-contiguous float copies, or None where the kernel is
        not loaded or refuses a state or the arguments (the numpy path then says why)."""
        kernel = KERNEL.ready or KERNEL.get()
        if kernel is None or D.shape[-1] != self.m or D.size == 0:
            return None
        table = np.empty((D.size // self.m, *shape))
        try:
            rates = [np.zeros(D.shape) if x is None else x for x in motion]
            arrays = [_rows(x, D.shape, self.m) for x in (D, *rates)]
            done = getattr(kernel, function)(self._code, self._constants, *arrays, table)
        except (TypeError, ValueError):  # types the kernel does not take, shapes that do not broadcast
            return None
        if not done:
            return None
        return table if D.ndim == 2 else table.reshape(D.shape[:-1] + shape)

    def pose(self, D: Any) -> np.ndarray:
        """Q (..., nq) for D (eq. 3 through the linkages, eqs. 1-2)."""
        if type(D) is not np.ndarray:  # (another dtype: the kernel refuses it, validate converts)
            D = np.asarray(D, dtype=float)
        if (Q := self._compiled("pose", "poses", self._pose_shapes, D)) is not None:
            return Q
        if D.ndim > 1 and (Q := self._batch("poses", self._pose_shapes[0], D)) is not None:
            return Q
        return self._solve(self.validate(D), every_pin=False).Q.p

    def joints(self, D: Any) -> np.ndarray:
        """theta (..., n), the main chain's joints for D."""
        return self._solve(self.validate(D), every_pin=False).theta.p

    def pins(self, D: Any) -> dict[str, np.ndarray]:
        """Every pin in the base frame (..., 3) under its machine-file name."""
        return self.solve_pins(self.validate(D))

    def solve_pins(self, D: np.ndarray) -> dict[str, np.ndarray]:
        """:meth:`pins` of states D (..., m) that the caller has checked (as :meth:`solve`)."""
        solved = self._solve(D)
        c, s = (np.cos(D[..., 0]), np.sin(D[..., 0])) if self.swing else (1.0, 0.0)
        out = {}
        for name, jet in solved.pins.items():
            r, z = jet.p[..., 0], jet.p[..., 1]
            out[name] = np.stack((r * c, r * s, z), axis=-1)
        return out

    def corners(self, D: Any) -> tuple[np.ndarray, np.ndarray]:
        """Left and right cutting-edge (or tool) corners (..., 3): tool point +- (w/2)(-s1, c1, 0)."""
        D = self.validate(D)
        Q = self._solve(D).Q.p
        t1 = D[..., 0] if self.swing else np.zeros(D.shape[:-1])
        half = 0.5 * self.description.width * np.stack((-np.sin(t1), np.cos(t1), np.zeros_like(t1)), axis=-1)
        return Q[..., :3] + half, Q[..., :3] - half

    def monitored(self, D: Any, D_dot: Any) -> tuple[list[str], np.ndarray, np.ndarray]:
        """The points an avoidance zone watches (:mod:`manipulator_kinematics.zones`,
        docs/zones.md) in the base frame with their velocities for actuator rates ``D_dot``:
        names, positions (..., P, 3), velocities (..., P, 3). Every pin, both tool corners (tool
        point +- w/2 across the boom plane), the tool body's ``tool.outline`` points on both side
        faces (one where the width is 0) and the tail (``swing.tail_radius`` behind the swing
        axis at each of ``swing.tail_heights``); velocities in closed form from the jets."""
        names, p, v, _ = self.monitored_motion(D, D_dot)
        return names, p, v

    def monitored_motion(self, D: Any, D_dot: Any) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`monitored` and the points' accelerations (..., P, 3) along the motion at the
        constant rates ``D_dot`` (the jets' second derivatives with D_ddot = 0, and the swing's
        centripetal and Coriolis terms): how a point's path curves, for the zones' check. One state
        (float arrays (m,)) runs compiled once the kernel is loaded (``kernel.monitored``, the
        program of :attr:`monitored_points`: a velocity IK calls this per command); the numpy path
        below is the reference and says why a state is refused."""
        points = self.monitored_points
        if type(D) is np.ndarray and D.ndim == 1 and (kernel := KERNEL.ready or KERNEL.get()) is not None:
            n = len(points.names)
            p, v, a = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
            program = points.program
            try:
                if kernel.monitored(
                    program.code, program.values, points.points, points.half, points.swing, D, D_dot, p, v, a
                ):
                    return list(points.names), p, v, a
            except TypeError:  # arguments of types the kernel does not take (_warm): numpy's
                pass
        D = self.validate(D)
        D_dot = _finite(D_dot, D.shape, "D_dot")
        solved = self._solve(D, D_dot)
        d = self.description
        tool = solved.bodies[d.tool_body]
        jets = [*solved.pins.values(), *(tool.point(np.array(xz, dtype=float)) for xz in d.outline)]
        r, z = (np.stack([jet.p[..., i] for jet in jets], axis=-1) for i in (0, 1))
        r_dot, z_dot = (np.stack([jet.v[..., i] for jet in jets], axis=-1) for i in (0, 1))
        r_ddot, z_ddot = (np.stack([jet.a[..., i] for jet in jets], axis=-1) for i in (0, 1))
        t1 = D[..., 0:1] if self.swing else np.zeros(D.shape[:-1] + (1,))
        w = D_dot[..., 0:1] if self.swing else np.zeros(D.shape[:-1] + (1,))
        c, s = np.cos(t1), np.sin(t1)
        p = np.stack((r * c, r * s, z), axis=-1)
        v = np.stack((r_dot * c - r * s * w, r_dot * s + r * c * w, z_dot), axis=-1)
        spin = r_ddot - r * w * w  # radial: the boom plane's own and the centripetal
        a = np.stack((spin * c - 2.0 * r_dot * s * w, spin * s + 2.0 * r_dot * c * w, z_ddot), axis=-1)
        n_pins = len(solved.pins)
        half = 0.5 * d.width
        zero = np.zeros_like(c)
        across = half * np.concatenate((-s, c, zero), axis=-1)[..., None, :]
        turning = half * np.concatenate((-c * w, -s * w, zero), axis=-1)[..., None, :]
        turned = half * np.concatenate((s * w * w, -c * w * w, zero), axis=-1)[..., None, :]
        Q = solved.Q
        tool_p, tool_v, tool_a = Q.p[..., None, :3], Q.v[..., None, :3], Q.a[..., None, :3]
        parts_p = [p[..., :n_pins, :], tool_p + across, tool_p - across]
        parts_v = [v[..., :n_pins, :], tool_v + turning, tool_v - turning]
        parts_a = [a[..., :n_pins, :], tool_a + turned, tool_a - turned]
        if d.outline:
            outline_p, outline_v, outline_a = p[..., n_pins:, :], v[..., n_pins:, :], a[..., n_pins:, :]
            if half > 0.0:
                parts_p += [outline_p + across, outline_p - across]
                parts_v += [outline_v + turning, outline_v - turning]
                parts_a += [outline_a + turned, outline_a - turned]
            else:
                parts_p.append(outline_p)
                parts_v.append(outline_v)
                parts_a.append(outline_a)
        if d.tail:
            radius, height = np.array(d.tail, dtype=float).T
            level = height * np.ones_like(c)
            parts_p.append(np.stack((-radius * c, -radius * s, level), axis=-1))
            parts_v.append(np.stack((radius * s * w, -radius * c * w, np.zeros_like(level)), axis=-1))
            parts_a.append(np.stack((radius * c * w * w, radius * s * w * w, np.zeros_like(level)), axis=-1))
        return (
            list(points.names),  # pack_monitored's: the same points in the same order
            np.concatenate(parts_p, axis=-2),
            np.concatenate(parts_v, axis=-2),
            np.concatenate(parts_a, axis=-2),
        )

    def measured(self, D: Any, D_dot: Any = None) -> HydraulicState:
        """:meth:`state` of a measurement: D (..., m) checked finite, not against the stroke box (a
        sensor a little beyond an end is still a state the forward node reports); Q and the rest
        are NaN where the linkage does not close there."""
        D = _finite(D, np.shape(D), "D")
        if D.ndim == 0 or D.shape[-1] != self.m:
            raise StrokeError(f"D: expected (..., {self.m}) values [{', '.join(self.actuator_names)}]")
        D_dot = np.zeros(D.shape) if D_dot is None else _finite(D_dot, D.shape, "D_dot")
        with np.errstate(invalid="ignore"):  # a dyad that does not close: NaN, the caller's to drop
            return self.solve(D, D_dot)

    def placements(self, D: Any) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Every body's frame in the boom plane: name -> (origin (..., 2) as (r, z), angle (...)
        counter-clockwise seen from the machine's right); D checked finite only, as :meth:`measured`
        (drawings of measured states)."""
        D = _finite(D, np.shape(D), "D")
        if D.ndim == 0 or D.shape[-1] != self.m:
            raise StrokeError(f"D: expected (..., {self.m}) values [{', '.join(self.actuator_names)}]")
        with np.errstate(invalid="ignore"):
            bodies = self._solve(D).bodies
        return {name: (body.origin.p, body.angle.p) for name, body in bodies.items()}

    def margins(self, D: Any) -> np.ndarray:
        """Dead-centre margin (rad) of every dyad (..., n_dyads), in the order of ``dyad_names``."""
        return self._solve(self.validate(D)).margins

    def k_matrix(self, D: Any) -> np.ndarray:
        """K = dtheta/dD (..., n, m) (eq. 7), from the implicitly differentiated dyads."""
        return self._solve(self.validate(D), every_pin=False).theta.J

    def jc0(self, D: Any) -> np.ndarray:
        """JC0 = dQ/dD (..., nq, m) (eq. 8), rows in Q's order."""
        if type(D) is not np.ndarray:
            D = np.asarray(D, dtype=float)
        if (J := self._compiled("jc0", "jc0s", self._jc0_shapes, D)) is not None:
            return J
        if D.ndim > 1 and (J := self._batch("jc0s", self._jc0_shapes[0], D)) is not None:
            return J
        return self._solve(self.validate(D), every_pin=False).Q.J

    def state(self, D: Any, D_dot: Any, D_ddot: Any = None) -> HydraulicState:
        """theta, Q and their rates and accelerations for cylinder states (eqs. 3, 7, 8, 10-11):
        Qddot = JC0 Dddot + (d/dt JC0) Ddot (the dyads' second derivatives along the motion)."""
        if type(D) is not np.ndarray:
            D = np.asarray(D, dtype=float)
        if (kernel := KERNEL.ready or KERNEL.get()) is not None:
            if D.ndim == 1:
                # The single call (a 1 kHz node calls it per message): the kernel checks lengths,
                # types and values; the numpy path below converts and raises the error for what it
                # refuses. Written out (no _compiled, no asarray of an array, no of_table): each
                # Python call costs 0.1-0.2 us, an eighth of the kernel's (docs/benchmarks.md).
                table = np.empty(self._table_shape)
                accelerations = self._no_acceleration if D_ddot is None else D_ddot
                try:
                    done = kernel.state(self._code, self._constants, D, D_dot, accelerations, table)
                except TypeError:  # not arrays of floats (_warm): once more as such
                    try:
                        rates = np.asarray(D_dot, dtype=float), np.asarray(accelerations, dtype=float)
                        done = kernel.state(self._code, self._constants, D, *rates, table)
                    except (TypeError, ValueError):  # the numpy path says why
                        done = False
            else:
                # A batch (N, m), the same steps as the single call: the rates as given, (N, m) or
                # one row for all (the kernel checks their rows; other shapes and types, D of
                # another dimension too: TypeError, _batch below), so that a batch of one costs
                # what a single call does (issue #32).
                accelerations = self._no_accelerations if D_ddot is None else D_ddot
                try:
                    n = len(D)
                    table = np.empty(self._table_one if n == 1 else (n, self._table_rows, 3 + self.m))
                    done = kernel.states(self._code, self._constants, D, D_dot, accelerations, table)
                except TypeError:
                    done = False
            if done:
                state = _NEW(HydraulicState)
                state._values, state._table, state._n = None, table, self._n
                return state
        if D.ndim > 1 and (tables := self._batch("states", self._table_shape, D, D_dot, D_ddot)) is not None:
            return HydraulicState.of_table(tables, self._n)
        D = self.validate(D)
        D_dot = _finite(D_dot, D.shape, "D_dot")
        return self.solve(D, D_dot, None if D_ddot is None else _finite(D_ddot, D.shape, "D_ddot"))

    def solve(self, D: np.ndarray, D_dot: Any = None, D_ddot: Any = None) -> HydraulicState:
        """The numpy core's :meth:`state` of states D (..., m) that the caller has checked: no
        check and no compiled path here, rates and accelerations (None: zero) broadcast to D's
        shape, NaN where a dyad does not close. For a model that holds this one and checks D its
        own way (the excavator's Excavator: its stroke tolerance, its continuous swing)."""
        D_dot = None if D_dot is None else np.broadcast_to(D_dot, D.shape)
        D_ddot = None if D_ddot is None else np.broadcast_to(D_ddot, D.shape)
        s = self._solve(D, D_dot, D_ddot, every_pin=False)
        return HydraulicState(s.theta.p, s.theta.v, s.theta.a, s.Q.p, s.Q.v, s.Q.a, s.Q.J, s.theta.J)

    # ------------------------------------------------------------------ open chain (eqs. 3-5)
    def _chain_geometry(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per main-chain joint: (the joint's point in the parent frame, its point in the child
        frame): the hinge pin, or the slide's axis point and the child origin."""
        d = self.description
        out = []
        for joint in d.joints:
            if joint.slide is None:
                out.append((d.bodies[joint.parent][joint.hinge], d.bodies[joint.child][joint.hinge]))
            else:
                out.append((np.asarray(joint.slide.axis_point, dtype=float), np.zeros(2)))
        return out

    def _open_chain(
        self, theta: np.ndarray
    ) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], dict[str, tuple[np.ndarray, np.ndarray]]]:
        """Boom-plane tool point (..., 2), each joint's point and its parent's angle, and each
        chain body's frame (origin, angle): eq. 3 for any chain of the family."""
        shape = theta.shape[:-1]
        origin, phi = np.zeros(shape + (2,)), np.zeros(shape)
        frames = {self.description.ground: (origin, phi)}
        points, parents = [], []
        for i, (joint, (in_parent, in_child)) in enumerate(
            zip(self.description.joints, self._chain_geometry(), strict=True)
        ):
            q = theta[..., i + int(self.swing)]
            if joint.slide is None:
                point = origin + _rot(phi, np.broadcast_to(in_parent, origin.shape))
                points.append(point)
                parents.append(phi)
                phi = phi + q
                origin = point - _rot(phi, np.broadcast_to(in_child, origin.shape))
            else:
                local = np.stack((in_parent[0] + q, np.full(shape, in_parent[1])), axis=-1)
                point = origin + _rot(phi, local)
                points.append(point)
                parents.append(phi)
                origin = point
            frames[joint.child] = (origin, phi)
        d = self.description
        tool = origin + _rot(phi, np.broadcast_to(d.bodies[d.tool_body][d.tool_pin], origin.shape))
        return tool, points, parents, frames

    def open_chain_pose(self, theta: Any) -> np.ndarray:
        """Q from the main chain's joints (eq. 3), no limits."""
        theta = np.asarray(theta, dtype=float)
        tool, *_ = self._open_chain(theta)
        r, z = tool[..., 0], tool[..., 1]
        t1 = theta[..., 0] if self.swing else np.zeros(r.shape)
        rows = [r * np.cos(t1), r * np.sin(t1), z]
        if self.description.has_angle:
            rows.append(np.sum(theta[..., self._revolute()], axis=-1))
        return np.stack(rows, axis=-1)

    def j0(self, theta: Any) -> np.ndarray:
        """J0 = dQ/dtheta (..., nq, n) (eqs. 4-5) in closed form: a revolute joint turns the tool
        point about its pin, d(r, z) = perp(T - P); a prismatic joint moves it along its parent's
        x axis; the swing turns (r, 0) about z; alpha gains 1 per revolute joint."""
        theta = np.asarray(theta, dtype=float)
        tool, points, parents, _ = self._open_chain(theta)
        cols = []
        for joint, point, phi in zip(self.description.joints, points, parents, strict=True):
            if joint.slide is None:
                cols.append(dyads.perp(tool - point))
            else:
                cols.append(np.stack((np.cos(phi), np.sin(phi)), axis=-1))
        plane = np.stack(cols, axis=-1)  # (..., 2, n_chain): rows r, z
        r = tool[..., 0]
        t1 = theta[..., 0] if self.swing else np.zeros(r.shape)
        c, s = np.cos(t1)[..., None], np.sin(t1)[..., None]
        rows = [c * plane[..., 0, :], s * plane[..., 0, :], plane[..., 1, :]]
        if self.description.has_angle:
            rows.append(
                np.array([0.0 if j.slide else 1.0 for j in self.description.joints]) + 0.0 * plane[..., 0, :]
            )
        J0 = np.stack(rows, axis=-2)
        if self.swing:
            swing = np.zeros(J0.shape[:-1] + (1,))
            swing[..., 0, 0], swing[..., 1, 0] = -r * np.sin(t1), r * np.cos(t1)
            J0 = np.concatenate((swing, J0), axis=-1)
        return J0

    # ------------------------------------------------------------------ inverses (eqs. 9, 12-13)
    def _solve_rows(self, jc0: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """D-space solution of JC0[rows] x = rhs[rows] in actuator-speed units (x = S u, S =
        diag(max_speed)): exact where the commanded rows are as many as the actuators and JC0 is
        regular, least squares where they are more, the smallest ||u|| where fewer
        (docs/hydraulic_family.md: what eq. 9 solves for a non-square JC0)."""
        rows = list(self.description.velocity_rows)
        A = jc0[..., rows, :] * self.max_speed
        # One SVD for both: the pseudo-inverse (numpy's pinv: singular values below 1e-15 of the
        # largest dropped) and the 2-norm condition number (numpy's cond: inf where singular);
        # pinv and cond made one each, 4-5x the rest of a single call.
        left, sigma, right = np.linalg.svd(A, full_matrices=False)
        with np.errstate(divide="ignore", invalid="ignore"):
            condition = sigma[..., 0] / sigma[..., -1]
        condition = np.where(np.isnan(condition), np.inf, condition)
        kept = sigma > 1e-15 * sigma[..., :1]
        inverse = np.divide(1.0, sigma, where=kept, out=np.zeros_like(sigma))
        u = right.swapaxes(-1, -2) @ (inverse[..., None] * (left.swapaxes(-1, -2) @ rhs[..., rows, None]))
        return u[..., 0] * self.max_speed, condition

    def cylinder_rates(self, D: Any, Q_dot: Any) -> RateSolution:
        """Ddot from a target task rate (eq. 9): JC0^-1 Qdot on the rows the machine commands
        (``tool.velocity_rows``); where JC0 is not square there, the least-squares or smallest
        (speed-scaled) solution, the task rates it gives returned with it."""
        D = self.validate(D)
        Q_dot = _finite(Q_dot, D.shape[:-1] + (len(self.task_names),), "Q_dot")
        jc0 = self.jc0(D)
        rates, condition = self._solve_rows(jc0, Q_dot)
        return RateSolution(rates, (jc0 @ rates[..., None])[..., 0], condition)

    def cylinder_accelerations(self, D: Any, D_dot: Any, Q_ddot: Any) -> np.ndarray:
        """Dddot = JC0^-1 (Qddot - (d/dt JC0) Ddot) (eqs. 12-13), on the commanded rows as in
        :meth:`cylinder_rates`."""
        D = self.validate(D)
        Q_ddot = _finite(Q_ddot, D.shape[:-1] + (len(self.task_names),), "Q_ddot")
        free = self.state(D, D_dot)  # Dddot = 0: the velocity-product terms alone
        return self._solve_rows(free.jc0, Q_ddot - free.Q_ddot)[0]

    # ------------------------------------------------------------------ position IK
    @cached_property
    def _inverse(self) -> list[tuple[str, str, str, float, float, int]] | None:
        """The linkage inverse's plan, made on first use (from the reference state, which a model
        built unchecked assembles only once its owner has checked it)."""
        return self._inverse_plan()

    def _inverse_plan(self) -> list[tuple[str, str, str, float, float, int]] | None:
        """The linkage inverse: with the main chain's bodies placed from theta, every other body
        placed from two known pins (body, pin, pin, 0, 0, 0) and every other pin solved as a dyad
        (X, A, B, r_A, r_B, branch) of pins already known, each side a fixed distance on one
        body (paper eqs. 1-2 inverted: given the joint angle, a cylinder's length is the distance
        of two known pins). Branches from the reference state. None where no such order exists
        (no closed form)."""
        d = self.description
        placed = {d.ground} | {j.child for j in d.joints}
        known = {p for b in placed for p in d.bodies[b]}
        pins = self._solve(self.reference).pins
        plan = []
        while len(placed) < len(d.bodies):
            progress = False
            for body in d.bodies:
                have = [p for p in d.bodies[body] if p in known]
                if body not in placed and len(have) >= 2:
                    plan.append((body, have[0], have[1], 0.0, 0.0, 0))
                    placed.add(body)
                    known.update(d.bodies[body])
                    progress = True
            for body in d.bodies:
                if body in placed or progress:
                    continue
                for x in d.bodies[body]:
                    centres = [
                        (a, float(np.linalg.norm(d.bodies[b][x] - d.bodies[b][a])))
                        for b in d.bodies
                        if x in d.bodies[b]
                        for a in d.bodies[b]
                        if a != x and a in known
                    ]
                    if x not in known and len(centres) >= 2:
                        (a, ra), (b, rb) = centres[:2]
                        pa, pb, px = pins[a].p, pins[b].p, pins[x].p
                        plan.append((x, a, b, ra, rb, int(np.sign(dyads.cross(pb - pa, px - pa)))))
                        known.add(x)
                        progress = True
                        break
            if not progress:
                return None
        return plan

    def _cylinders_from_theta(self, theta: np.ndarray) -> np.ndarray:
        """D (..., m) from the main chain's joints: chain bodies placed (eq. 3), the linkage
        inverse (:meth:`_inverse_plan`), each cylinder's length the distance of its pins."""
        d = self.description
        *_, frames = self._open_chain(theta)
        known = {}
        for body, (origin, phi) in frames.items():
            for pin, local in d.bodies[body].items():
                known[pin] = origin + _rot(phi, np.broadcast_to(local, origin.shape))
        if self._inverse is None:
            raise NotImplementedError(f"{d.name}: no closed-form inverse of its linkage")
        for x, a, b, ra, rb, branch in self._inverse:
            if branch:
                known[x] = dyads.intersect(known[a], known[b], ra, rb, branch)[0]
                continue
            one, two = d.bodies[x][a], d.bodies[x][b]  # place body x through its pins a and b
            e, local = known[b] - known[a], two - one
            phi = np.arctan2(e[..., 1], e[..., 0]) - np.arctan2(local[1], local[0])
            for pin, xz in d.bodies[x].items():
                known.setdefault(pin, known[a] + _rot(phi, np.broadcast_to(xz - one, e.shape)))
        columns = [theta[..., 0]] if self.swing else []
        for c in d.cylinders:
            slide = next((j.slide for j in d.joints if j.slide and j.slide.index == c.index), None)
            if slide is not None:  # the telescope: its length is the joint itself
                i = d.joints.index(next(j for j in d.joints if j.slide is slide)) + int(self.swing)
                columns.append(theta[..., i] - slide.offset)
            else:
                columns.append(np.linalg.norm(known[c.rod] - known[c.base], axis=-1))
        return np.stack(columns, axis=-1)

    def ik(self, Q: Any, seed: Any = None) -> IKResult:
        """D for a task vector Q (..., nq), closed form: the swing from (x, y); the main chain as a
        dyad (two revolute joints: the second pivot at the first link's length from the first
        pivot and at the second link's from the wrist), both elbow branches tried; the wrist from
        alpha where a third revolute joint follows, the extension of ``seed`` (default: the
        reference) where a prismatic joint follows; then the linkage inverse. The branch inside
        the stroke box and nearest ``seed`` wins; ``valid`` is False where none is, or where Q is
        not reachable (the loader: (x, z, alpha) with two actuators). No numerical fallback: a
        machine whose chain or linkage has no such closed form raises NotImplementedError."""
        Q = np.asarray(Q, dtype=float)
        nq = len(self.task_names)
        if Q.ndim == 0 or Q.shape[-1] != nq:
            raise StrokeError(f"Q: expected (..., {nq}) values [{', '.join(self.task_names)}], got {Q.shape}")
        seed = np.broadcast_to(
            self.reference if seed is None else np.asarray(seed, dtype=float), Q.shape[:-1] + (self.m,)
        )
        return self._ik(Q, seed)

    def position_ik(self, position: Any, seed: Any = None) -> IKResult:
        """D for a tool point (..., 3): :meth:`ik` with the tool angle of ``seed`` held (default:
        the reference state) where Q has one; the loader's two joints are fixed by (x, z) alone."""
        position = np.asarray(position, dtype=float)
        seed = np.broadcast_to(
            self.reference if seed is None else np.asarray(seed, dtype=float), position.shape[:-1] + (self.m,)
        )
        if not self.description.has_angle:
            return self.ik(position, seed)
        revolute = sum(j.slide is None for j in self.description.joints)
        alpha = self._solve(self.validate(seed)).Q.p[..., 3]
        return self._ik(np.concatenate((position, alpha[..., None]), axis=-1), seed, use_alpha=revolute > 2)

    def _ik(self, Q: np.ndarray, seed: np.ndarray, use_alpha: bool = True) -> IKResult:
        d = self.description
        joints = d.joints
        if self._inverse is None or len(joints) < 2 or joints[0].slide or joints[1].slide or len(joints) > 3:
            raise NotImplementedError(f"{d.name}: no closed-form IK for this chain or linkage")
        x, y, z = Q[..., 0], Q[..., 1], Q[..., 2]
        seed_theta = self._solve(self.validate(seed)).theta.p
        best_D = np.full(Q.shape[:-1] + (self.m,), np.nan)
        best_cost = np.full(Q.shape[:-1], np.inf)
        # The swing: (x, y) = r (cos theta1, sin theta1) with r of either sign (a tool behind the
        # swing axis) and theta1 in any turn its limits allow; without swing, r = x.
        if self.swing:
            turns = [(np.arctan2(y, x) + k * np.pi, (-1) ** k * np.hypot(x, y)) for k in (-2, -1, 0, 1, 2)]
        else:
            turns = [(None, x)]
        for theta1, r in turns:
            self._ik_plane(
                Q, seed, seed_theta, theta1, np.stack((r, z), axis=-1), use_alpha, best_D, best_cost
            )
        return IKResult(best_D, np.isfinite(best_cost))

    def _ik_plane(
        self,
        Q: np.ndarray,
        seed: np.ndarray,
        seed_theta: np.ndarray,
        theta1: np.ndarray | None,
        target: np.ndarray,
        use_alpha: bool,
        best_D: np.ndarray,
        best_cost: np.ndarray,
    ) -> None:
        """The main chain for one swing candidate, both elbow branches; ``best_D``/``best_cost``
        updated in place where a valid D is nearer the seed (stroke-scaled)."""
        d = self.description
        ja, jb, rest = d.joints[0], d.joints[1], d.joints[2:]
        A, B = d.bodies[ja.child], d.bodies[jb.child]
        tool_local = d.bodies[d.tool_body][d.tool_pin]
        if not rest:
            w_local, wrist = tool_local, target
        elif rest[0].slide is not None:
            i = 2 + int(self.swing)
            s = seed_theta[..., i]
            axis = np.asarray(rest[0].slide.axis_point)
            w_local = np.stack(
                (axis[0] + s + tool_local[0], np.full(s.shape, axis[1] + tool_local[1])), axis=-1
            )
            wrist = target
        else:
            if not d.has_angle:
                raise NotImplementedError(f"{d.name}: three revolute joints need the tool angle")
            tool_body = d.bodies[rest[0].child]
            w_local = B[rest[0].hinge]
            back = tool_local - tool_body[rest[0].hinge]
            wrist = target - _rot(Q[..., 3], np.broadcast_to(back, target.shape))
        pa = np.broadcast_to(d.bodies[d.ground][ja.hinge], target.shape)
        l1 = float(np.linalg.norm(A[jb.hinge] - A[ja.hinge]))
        arm = np.broadcast_to(w_local - B[jb.hinge], target.shape)
        l2 = np.linalg.norm(arm, axis=-1)
        link = A[jb.hinge] - A[ja.hinge]
        for branch in (1, -1):
            pb, h2 = dyads.intersect(pa, wrist, l1, l2, branch)
            phi_a = np.arctan2(pb[..., 1] - pa[..., 1], pb[..., 0] - pa[..., 0]) - np.arctan2(
                link[1], link[0]
            )
            phi_b = np.arctan2(wrist[..., 1] - pb[..., 1], wrist[..., 0] - pb[..., 0]) - np.arctan2(
                arm[..., 1], arm[..., 0]
            )
            cols = [theta1] if theta1 is not None else []
            cols += [_wrap(phi_a), _wrap(phi_b - phi_a)]
            if rest and rest[0].slide is not None:
                cols.append(seed_theta[..., 2 + int(self.swing)])
            elif rest:
                cols.append(_wrap(Q[..., 3] - phi_b))
            theta = np.stack(cols, axis=-1)
            with np.errstate(invalid="ignore"):
                D = self._cylinders_from_theta(theta)
                inside = np.all((self.lower <= D) & (self.upper >= D), axis=-1) & (h2 > 0)
                # FK of the D found (not of theta): a linkage inverse off its branch shows here
                reached = self._solve(np.where(inside[..., None], D, self.reference)).Q.p
                rows = slice(None) if use_alpha else slice(0, 3)
                ok = inside & np.all(np.abs(reached[..., rows] - Q[..., rows]) < 1e-9, axis=-1)
            cost = np.where(ok, np.sum(((D - seed) / (self.upper - self.lower)) ** 2, axis=-1), np.inf)
            better = cost < best_cost
            best_D[...] = np.where(better[..., None], D, best_D)
            best_cost[...] = np.where(better, cost, best_cost)


_NEW = object.__new__


def _rows(values: Any, shape: tuple[int, ...], m: int) -> np.ndarray:
    """``values`` broadcast to ``shape`` as a C-contiguous, writeable float array (N, m): what the
    kernel's loops take (a view where it is one already, else a copy)."""
    array = np.asarray(values, dtype=float)
    if array.shape != shape or not array.flags.carray:  # carray: C-contiguous, aligned, writeable
        array = np.array(np.broadcast_to(array, shape), order="C")
    return array if array.ndim == 2 else array.reshape(-1, m)


def _finite(values: Any, shape: tuple[int, ...], name: str) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    try:
        array = np.broadcast_to(array, shape)
    except ValueError:
        raise StrokeError(f"{name}: expected shape {shape}, got {array.shape}") from None
    if not np.all(np.isfinite(array)):
        raise StrokeError(f"{name}: values must be finite")
    return array
