"""A family machine's solve plan packed once into the compiled kernel's program (the layout:
:mod:`manipulator_kinematics.hydraulic.layout`), from the same
:class:`~manipulator_kinematics.hydraulic.description.Description` the numpy core
(:class:`~manipulator_kinematics.hydraulic.model.HydraulicModel`) runs: the same steps in the same
order, each pin computed once, and only the pins a later step or the tool reads (the single
call's work; :meth:`HydraulicModel.pins` stays on the numpy path). The monitored points of the
avoidance zones (:func:`pack_monitored`) have a program of their own that makes every pin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from manipulator_kinematics.hydraulic.description import Description, Dyad, Place, Radius, Slide
from manipulator_kinematics.hydraulic.layout import FLOAT, INT, OP, POINT

__all__ = ["Monitored", "Program", "pack", "pack_monitored"]


@dataclass(frozen=True)
class Program:
    """The packed plan: ``code`` (rows, len(INT)) int64, ``values`` (rows, len(FLOAT)) float64;
    the kernel's result table of one state is (n + nq, 3 + m): per theta then Q entry its value,
    rate, acceleration and its row of d/dD."""

    code: np.ndarray
    values: np.ndarray
    n: int
    nq: int
    m: int


class _Writer:
    """Rows of the program and slot numbers, given out in order."""

    def __init__(self) -> None:
        self.rows: list[tuple[dict[str, int], dict[str, float]]] = []
        self.slots = 0

    def slot(self, count: int = 1) -> int:
        first, self.slots = self.slots, self.slots + count
        return first

    def emit(
        self, op: int, ints: dict[str, int] | None = None, floats: dict[str, float] | None = None
    ) -> None:
        self.rows.append(({"op": op, **(ints or {})}, floats or {}))


def _radius(side: Radius) -> tuple[int, float]:
    return (-1, side.fixed) if side.index is None else (side.index, 0.0)


def pack(d: Description, lower: np.ndarray, upper: np.ndarray) -> Program:
    """The program of ``d`` with the stroke box [lower, upper] (module docstring)."""
    return _pack(d, lower, upper)[0]


@dataclass(frozen=True)
class Monitored:
    """The monitored points' program (every pin made, then the tool outline's points and the
    tail's) with its point table ``points`` (P, len(POINT)) int64, the points' ``names`` in the
    table's order (:meth:`HydraulicModel.monitored_motion`'s), half the tool width ``half`` and
    the swing's column of D (-1: no swing)."""

    program: Program
    points: np.ndarray
    names: tuple[str, ...]
    half: float
    swing: int


def pack_monitored(d: Description, lower: np.ndarray, upper: np.ndarray) -> Monitored:
    """The monitored points of ``d`` (layout module docstring): every pin under its name in the
    order the numpy solve makes them, both tool corners (``left_corner``, ``right_corner``: the
    tool point half the width to either side), the tool outline on both side faces
    (``tool_outline_<i>_left``, ``_right``; one ``tool_outline_<i>`` where the width is 0) and the
    tail (``tail_<i>``)."""
    program, pins, extra = _pack(d, lower, upper, every_pin=True)
    half = 0.5 * d.width
    rows = [(slot, 0) for slot in pins.values()]
    tool = pins[d.tool_pin]
    rows += [(tool, 1), (tool, -1)]
    names = [*pins, "left_corner", "right_corner"]
    outline = extra[: len(d.outline)]
    if outline and half > 0.0:
        rows += [(slot, side) for side in (1, -1) for slot in outline]
        names += [f"tool_outline_{i}_{side}" for side in ("left", "right") for i in range(len(outline))]
    else:
        rows += [(slot, 0) for slot in outline]
        names += [f"tool_outline_{i}" for i in range(len(outline))]
    rows += [(slot, 0) for slot in extra[len(d.outline) :]]
    names += [f"tail_{i}" for i in range(len(d.tail))]
    points = np.zeros((len(rows), len(POINT)), dtype=np.int64)
    for row, (slot, side) in enumerate(rows):
        points[row, POINT.slot], points[row, POINT.side] = slot, side
    swing = 0 if d.swing is not None else -1
    return Monitored(program, points, tuple(names), half, swing)


def _pack(
    d: Description, lower: np.ndarray, upper: np.ndarray, every_pin: bool = False
) -> tuple[Program, dict[str, int], list[int]]:
    """The program, its pins' slots and the extra points':
    only the pins a later step reads, or ``every_pin`` (the monitored points' program: every pin,
    then the tool outline's points and the tail's, whose slots come last)."""
    w = _Writer()
    m, swing = len(lower), d.swing is not None
    n = int(swing) + len(d.joints)
    nq = len(d.task_names)
    results = w.slot(n + nq)  # theta, then Q: the result table's rows
    for i in range(m):
        w.emit(OP.limit, {"act": i}, {"x": float(lower[i]), "z": float(upper[i])})

    # Pins read after they are made: dyad centres, placing pins (the tool point is its own).
    read = {pin for step in d.steps if isinstance(step, Dyad) for pin in (step.pivot, step.first)}
    read |= {pin for step in d.steps if isinstance(step, Place) for pin in (step.one, step.two)}
    if every_pin:
        read |= {pin for pins in d.bodies.values() for pin in pins}
    pins: dict[str, int] = {}
    origin: dict[str, int] = {}
    angle: dict[str, int] = {}

    def point(body: str, xz: tuple[float, float] | np.ndarray) -> int:
        slot = w.slot()
        w.emit(
            OP.point,
            {"out": slot, "p": origin[body], "angle": angle[body]},
            {"x": float(xz[0]), "z": float(xz[1])},
        )
        return slot

    def points(body: str) -> None:
        for pin, xz in d.bodies[body].items():
            if pin in read and pin not in pins:
                pins[pin] = point(body, xz)

    origin[d.ground], angle[d.ground] = w.slot(), w.slot()
    w.emit(OP.fixed, {"out": origin[d.ground]}, {"x": 0.0, "z": 0.0})
    w.emit(OP.fixed, {"out": angle[d.ground]}, {"x": 0.0, "z": 0.0})
    for pin, xz in d.bodies[d.ground].items():  # the ground frame is the base: the pins as given
        if pin in read:
            pins[pin] = w.slot()
            w.emit(OP.fixed, {"out": pins[pin]}, {"x": float(xz[0]), "z": float(xz[1])})
    for step in d.steps:
        if isinstance(step, Dyad):
            (act, length), (act2, length2) = _radius(step.pivot_radius), _radius(step.first_radius)
            pins[step.pin] = w.slot()
            w.emit(
                OP.dyad,
                {
                    "out": pins[step.pin],
                    "p": pins[step.pivot],
                    "q": pins[step.first],
                    "act": act,
                    "act2": act2,
                },
                {"length": length, "length2": length2, "sign": float(step.orientation)},
            )
        elif isinstance(step, Place):
            local = d.bodies[step.body]
            one, two = local[step.one], local[step.two]
            origin[step.body], angle[step.body] = w.slot(), w.slot()
            phase = math.atan2(two[1] - one[1], two[0] - one[0])
            w.emit(
                OP.place,
                {
                    "out": origin[step.body],
                    "angle": angle[step.body],
                    "p": pins[step.one],
                    "q": pins[step.two],
                },
                {"x": float(one[0]), "z": float(one[1]), "cos": math.cos(phase), "sin": math.sin(phase)},
            )
            points(step.body)
        else:
            _slide(w, step, origin, angle)
            points(step.child)

    # theta: the swing, then each joint (eq. 3's chain); Q: x, y, z from the tool point, alpha.
    if swing:
        w.emit(OP.actuator, {"out": results, "act": 0}, {"length": 0.0})
    alpha = results + n + 3
    revolute = []
    for i, joint in enumerate(d.joints, start=results + int(swing)):
        if joint.slide is not None:
            w.emit(OP.actuator, {"out": i, "act": joint.slide.index}, {"length": joint.slide.offset})
        else:
            w.emit(OP.angle, {"out": i, "p": angle[joint.child], "q": angle[joint.parent]})
            revolute.append(i)
    tool = point(d.tool_body, d.bodies[d.tool_body][d.tool_pin])
    w.emit(OP.task, {"out": results + n, "p": tool, "act": 0 if swing else -1})
    if d.has_angle:
        w.emit(OP.fixed, {"out": alpha}, {"x": 0.0, "z": 0.0})
        for i in revolute:
            w.emit(OP.add, {"out": alpha, "p": i})
    extra: list[int] = []
    if every_pin:
        extra = [point(d.tool_body, xz) for xz in d.outline]
        for radius, height in d.tail:  # behind the swing axis: r = -radius
            extra.append(w.slot())
            w.emit(OP.fixed, {"out": extra[-1]}, {"x": -float(radius), "z": float(height)})

    head = {"op": OP.head, "out": w.slots, "p": results, "act": n, "q": nq, "act2": m}
    code = np.full((1 + len(w.rows), len(INT)), -1, dtype=np.int64)
    values = np.zeros((1 + len(w.rows), len(FLOAT)))
    for row, (ints, floats) in enumerate([(head, {}), *w.rows]):
        for field, number in ints.items():
            code[row, getattr(INT, field)] = number
        for field, value in floats.items():
            values[row, getattr(FLOAT, field)] = value
    return Program(code, values, n, nq, m), pins, extra


def _slide(w: _Writer, step: Slide, origin: dict[str, int], angle: dict[str, int]) -> None:
    """The prismatic child: its origin slides along the parent's x axis; its angle is the parent's."""
    origin[step.child] = w.slot()
    angle[step.child] = angle[step.parent]
    w.emit(
        OP.slide,
        {"out": origin[step.child], "p": origin[step.parent], "angle": angle[step.parent], "act": step.index},
        {"x": float(step.axis_point[0]), "z": float(step.axis_point[1]), "length": step.offset},
    )
