"""Measure-up calibration of a hydraulic-family machine from total-station points (issue 33).

A real machine differs from its drawing by centimetres at the pins, and its sensors read with
zero offsets (true = reading + offset). Given points measured by a levelled total station in its own
frame (the tool tip, the cutting-edge corners, any pin of the machine file) at poses whose sensor
readings are known, :func:`calibrate` fits, by bounded nonlinear least squares
(``scipy.optimize.least_squares``), starting from the drawing:

* every pin's (x, z) in the frame of its body and every link's length,
* every cylinder's zero offset,
* the instrument-to-base transform (rotation vector and translation, 6 DoF),

minimising the 3-D distances of measured and predicted points weighted by their sigma.

**Gauge freedoms** (choices the data cannot see) are held at the drawing and named:

* each body's own frame (its origin pin and the zero z of its x-axis pin): a choice of
  coordinates, not of geometry;
* with a swing, the swing zero against the instrument heading (the swing's zero offset), and the
  base origin along the swing axis against the instrument (the height of the first joint's pivot);
* without a swing, the base origin (the first joint's pivot) and the base pitch against the
  instrument (one coordinate of another ground pin).

**Observability.** The weighted Jacobian J (residuals in sigma, parameters in metres; an angle
counts as its arc at :data:`REACH`) is decomposed at the drawing, J = U S V^T. A combination v_i
of the parameters is determined to 1/s_i; where that exceeds ``tolerance`` it is *not observable*
(an exact gauge at s_i ~ 0, e.g. a cylinder's two pins turned together about their hinge; a weak
one, e.g. a cylinder's zero offset against moving its pin along the cylinder with tip points
alone). The fit runs in the span of the other directions: the not-observable combinations stay at
the drawing, so that of the equivalent geometries the one closest to the drawing is found. For
each, the report says which extra points (a pin measured at the same poses) or poses (a cylinder
at its stroke ends) would determine it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.linalg import qr
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from manipulator_kinematics.hydraulic import dyads
from manipulator_kinematics.hydraulic.description import Description, Dyad, Place, Slide

__all__ = [
    "REACH",
    "Calibration",
    "CalibrationError",
    "Geometry",
    "Measurements",
    "Parameter",
    "calibrate",
]

#: An angle parameter counts as its arc at this radius (m) when directions are compared.
REACH = 5.0
#: The bound on a pin coordinate, a link length, a cylinder's zero offset (m) and the swing's (rad)
#: around the drawing.
PIN_BOUND, OFFSET_BOUND, SWING_BOUND = 0.2, 0.2, 0.2
TIP, LEFT, RIGHT = "tip", "left_corner", "right_corner"


class CalibrationError(ValueError):
    """Data the fit cannot use, or a fit that failed; the message is one line."""


@dataclass(frozen=True)
class Parameter:
    """One fitted or held quantity: ``name`` is its machine-file key (``bodies.boom.pins.arm_pin.x``,
    ``links.h_link.length``, ``cylinders.arm_cylinder.zero_offset``, ``swing.zero_offset``) or
    ``instrument.rx|ry|rz`` (rotation vector, rad) / ``instrument.tx|ty|tz`` (m)."""

    name: str
    drawing: float
    scale: float  # metres per unit of the compared direction (1, or 1/REACH for an angle)
    bound: float  # allowed distance from the drawing (inf: none)
    held: str = ""  # why held (a gauge), empty if fitted


@dataclass(frozen=True)
class Measurements:
    """Measured points: ``readings`` (N, m) per row, ``point`` names, ``xyz`` (N, 3) in the
    instrument frame, ``sigma`` (N,) and the ``pose`` label of each row; ``sigma_given``: the
    sigmas are the crew's (a CSV column), not the default."""

    pose: tuple[str, ...]
    readings: np.ndarray
    point: tuple[str, ...]
    xyz: np.ndarray
    sigma: np.ndarray
    sigma_given: bool = False


class Geometry:
    """The machine's points (pins, tip, corners) in the instrument frame as a function of the
    parameter vector: a position-only solve of the description's plan (docs/hydraulic_family.md)
    with every radius recomputed from the parameters."""

    def __init__(self, description: Description) -> None:
        self.description = d = description
        self.links = {b for b, pins in d.bodies.items() if len(pins) == 2 and _is_link(pins)}
        self.slides = [step for step in d.steps if isinstance(step, Slide)]
        self.parameters = self._parameters()
        self.index = {p.name: i for i, p in enumerate(self.parameters)}
        self.drawing = np.array([p.drawing for p in self.parameters])
        self.scale = np.array([p.scale for p in self.parameters])
        owners: dict[str, list[str]] = {}
        for body, pins in d.bodies.items():
            for pin in pins:
                owners.setdefault(pin, []).append(body)
        self.owners = owners
        self.pin_names = tuple(owners)
        self.point_names = (TIP, LEFT, RIGHT, *self.pin_names)

    # ------------------------------------------------------------------ parameters
    def _parameters(self) -> list[Parameter]:
        d = self.description
        out: list[Parameter] = []
        pivot = d.joints[0].pivot
        for body, pins in d.bodies.items():
            if body in self.links:
                one, two = pins
                out.append(
                    Parameter(
                        f"links.{body}.length", float(np.linalg.norm(pins[two] - pins[one])), 1.0, PIN_BOUND
                    )
                )
                continue
            held = self._held(body, pins, pivot)
            for pin, xz in pins.items():
                for k, axis in enumerate("xz"):
                    why = held.get((pin, axis), "")
                    out.append(
                        Parameter(f"bodies.{body}.pins.{pin}.{axis}", float(xz[k]), 1.0, PIN_BOUND, why)
                    )
        # The tool's width: the corners' distance (fitted when corners are measured); a tool
        # drawn without one (a crane's rotator pin) has no corners to fit.
        edgeless = "the tool has no cutting edge (width 0 in the drawing)" if d.width == 0.0 else ""
        out.append(Parameter("tool.width", float(d.width), 1.0, PIN_BOUND, edgeless))
        for slide in self.slides:
            key = f"prismatic.{slide.name}"
            # Along the slide, the axis point and the offset move the child exactly as the
            # cylinder's zero offset does: one quantity, fitted as that offset.
            cylinder = next(c.name for c in d.cylinders if c.index == slide.index)
            same = f"gauge: along the slide the same as cylinders.{cylinder}.zero_offset"
            out.append(Parameter(f"{key}.axis_point.x", slide.axis_point[0], 1.0, PIN_BOUND, same))
            out.append(Parameter(f"{key}.axis_point.z", slide.axis_point[1], 1.0, PIN_BOUND))
            out.append(Parameter(f"{key}.offset", slide.offset, 1.0, PIN_BOUND, same))
        if d.swing:
            out.append(
                Parameter(
                    "swing.zero_offset",
                    float(d.swing["zero_offset"]),
                    1.0 / REACH,
                    SWING_BOUND,
                    "gauge: the swing zero against the instrument heading",
                )
            )
        for c in d.cylinders:
            out.append(Parameter(f"cylinders.{c.name}.zero_offset", c.zero_offset, 1.0, OFFSET_BOUND))
        for axis in "xyz":
            out.append(Parameter(f"instrument.r{axis}", 0.0, 1.0 / REACH, math.inf))
        for axis in "xyz":
            out.append(Parameter(f"instrument.t{axis}", 0.0, 1.0, math.inf))
        return out

    def _held(
        self, body: str, pins: Mapping[str, np.ndarray], pivot: str | None
    ) -> dict[tuple[str, str], str]:
        """The gauge coordinates of a body: for the ground, the base frame against the instrument;
        for any other body, its own frame (an anchor pin, and the coordinate of the farthest pin
        that a turn about the anchor moves most)."""
        d = self.description
        if body == d.ground:
            if d.swing:
                return {(pivot, "z"): "gauge: the base origin along the swing axis against the instrument"}
            anchor = pivot
            why = "gauge: the base origin against the instrument (no swing)"
            turn = "gauge: the base pitch against the instrument (no swing)"
        else:
            anchor = next((p for p, xz in pins.items() if not np.any(xz)), next(iter(pins)))
            why = turn = f"the frame of body {body} (a choice of coordinates)"
        held = {(anchor, "x"): why, (anchor, "z"): why}
        others = [p for p in pins if p != anchor]
        if others:
            # the x-axis pin of a body drawn the way docs/hydraulic_family.md asks (the tool point
            # stays on the tool body's x axis, so alpha keeps its meaning), else the farthest pin
            on_axis = [p for p in others if body != d.ground and pins[p][1] == 0.0 and pins[p][0] > 0.0]
            far = max(on_axis or others, key=lambda p: float(np.linalg.norm(pins[p] - pins[anchor])))
            r = pins[far] - pins[anchor]
            held[(far, "x" if abs(r[1]) > abs(r[0]) else "z")] = turn
        return held

    # ------------------------------------------------------------------ forward
    def locals_(self, p: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
        """Body -> pin -> local (x, z) for parameters p."""
        out: dict[str, dict[str, np.ndarray]] = {}
        for body, pins in self.description.bodies.items():
            if body in self.links:
                one, two = pins
                out[body] = {one: np.zeros(2), two: np.array([p[self.index[f"links.{body}.length"]], 0.0])}
            else:
                out[body] = {
                    pin: np.array([p[self.index[f"bodies.{body}.pins.{pin}.{a}"]] for a in "xz"])
                    for pin in pins
                }
        return out

    def offsets(self, p: np.ndarray) -> np.ndarray:
        d = self.description
        swing = [p[self.index["swing.zero_offset"]]] if d.swing else []
        return np.array(swing + [p[self.index[f"cylinders.{c.name}.zero_offset"]] for c in d.cylinders])

    @staticmethod
    def instrument_from_base(p: np.ndarray, index: Mapping[str, int]) -> np.ndarray:
        """The 4x4 transform x_instrument = R x_base + t of parameters p."""
        T = np.eye(4)
        T[:3, :3] = Rotation.from_rotvec([p[index[f"instrument.r{a}"]] for a in "xyz"]).as_matrix()
        T[:3, 3] = [p[index[f"instrument.t{a}"]] for a in "xyz"]
        return T

    def _solve(self, p: np.ndarray, D: np.ndarray) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Every pin (N, 2) in the boom plane and every body's (origin, angle) at true states D."""
        d = self.description
        local = self.locals_(p)
        n = D.shape[0]
        pins = {pin: np.broadcast_to(xz, (n, 2)) for pin, xz in local[d.ground].items()}
        frames: dict[str, tuple[np.ndarray, np.ndarray]] = {d.ground: (np.zeros((n, 2)), np.zeros(n))}

        def put(body: str, origin: np.ndarray, phi: np.ndarray) -> None:
            frames[body] = (origin, phi)
            for pin, xz in local[body].items():
                if pin not in pins:
                    pins[pin] = origin + _turn(phi, xz)

        for step in d.steps:
            if isinstance(step, Dyad):
                ra = self._radius(local, step.pivot_radius, step.pivot, step.pin, D)
                rb = self._radius(local, step.first_radius, step.first, step.pin, D)
                pins[step.pin], _ = dyads.intersect(
                    pins[step.pivot], pins[step.first], ra, rb, step.orientation
                )
            elif isinstance(step, Place):
                l1, l2 = local[step.body][step.one], local[step.body][step.two]
                e = pins[step.two] - pins[step.one]
                phi = np.arctan2(e[:, 1], e[:, 0]) - math.atan2(l2[1] - l1[1], l2[0] - l1[0])
                put(step.body, pins[step.one] - _turn(phi, l1), phi)
            else:
                origin, phi = frames[step.parent]
                key = f"prismatic.{step.name}"
                ax, az, offset = (
                    p[self.index[f"{key}.{k}"]] for k in ("axis_point.x", "axis_point.z", "offset")
                )
                s = D[:, step.index] + offset
                put(step.child, origin + _turn(phi, np.stack((ax + s, np.full(n, az)), axis=-1)), phi)
        return pins, frames

    def joints(self, p: np.ndarray, D: np.ndarray) -> np.ndarray:
        """The main chain's revolute joints (N, n) (rad), NaN for a prismatic one."""
        _, frames = self._solve(p, D)
        out = [
            frames[j.child][1] - frames[j.parent][1] if j.slide is None else np.full(len(D), np.nan)
            for j in self.description.joints
        ]
        return np.pi - np.mod(np.pi - np.stack(out, axis=-1), 2.0 * np.pi)

    def base_points(self, p: np.ndarray, D: np.ndarray) -> dict[str, np.ndarray]:
        """Every pin, the tip and the corners (N, 3) in the base frame at true states D (N, m)."""
        d = self.description
        n = D.shape[0]
        pins, _ = self._solve(p, D)
        t1 = D[:, 0] if d.swing else np.zeros(n)
        c, s = np.cos(t1), np.sin(t1)
        out = {name: np.stack((xz[:, 0] * c, xz[:, 0] * s, xz[:, 1]), axis=-1) for name, xz in pins.items()}
        half = 0.5 * p[self.index["tool.width"]] * np.stack((-s, c, np.zeros(n)), axis=-1)
        out[TIP] = out[d.tool_pin]
        out[LEFT], out[RIGHT] = out[TIP] + half, out[TIP] - half
        return out

    def _radius(
        self, local: dict[str, dict[str, np.ndarray]], side: Any, centre: str, pin: str, D: np.ndarray
    ) -> np.ndarray | float:
        if side.index is not None:
            return D[:, side.index]
        body = next(b for b in self.owners[pin] if centre in local[b])
        return float(np.linalg.norm(local[body][pin] - local[body][centre]))

    def predict(self, p: np.ndarray, readings: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """The points ``names[i]`` (N, 3) at readings (N, m) in the instrument frame."""
        D = readings + self.offsets(p)
        points = self.base_points(p, D)
        T = self.instrument_from_base(p, self.index)
        base = np.empty((len(names), 3))
        for name in set(names):
            rows = np.array([k for k, n in enumerate(names) if n == name])
            base[rows] = points[name][rows]
        return base @ T[:3, :3].T + T[:3, 3]


def _is_link(pins: Mapping[str, np.ndarray]) -> bool:
    one, two = pins.values()
    return not np.any(one) and two[1] == 0.0 and two[0] > 0.0


def _turn(phi: np.ndarray, xz: np.ndarray) -> np.ndarray:
    c, s = np.cos(phi), np.sin(phi)
    xz = np.broadcast_to(xz, (len(phi), 2))
    return np.stack((c * xz[:, 0] - s * xz[:, 1], s * xz[:, 0] + c * xz[:, 1]), axis=-1)


@dataclass
class Calibration:
    """The result of :func:`calibrate`."""

    geometry: Geometry
    values: np.ndarray  # every parameter, fitted or held
    std: np.ndarray  # its standard deviation (0 where held)
    held_share: np.ndarray  # per parameter, the share (0..1) of it in not-observable combinations
    not_observable: list[dict[str, Any]]
    held: list[dict[str, str]]
    residuals: np.ndarray  # (N, 3) predicted - measured (m)
    drawing_residuals: np.ndarray  # (N, 3) of the drawing (with the best instrument placement)
    measurements: Measurements
    cost: dict[str, Any] = field(default_factory=dict)

    @property
    def instrument_from_base(self) -> np.ndarray:
        return Geometry.instrument_from_base(self.values, self.geometry.index)

    def value(self, name: str) -> float:
        return float(self.values[self.geometry.index[name]])


def _placement(geometry: Geometry, p: np.ndarray, data: Measurements) -> np.ndarray:
    """p with the instrument transform that best aligns the predicted points to the measured ones
    (weighted Kabsch, scipy's ``Rotation.align_vectors``)."""
    p = p.copy()
    idx = geometry.index
    for a in "xyz":
        p[idx[f"instrument.r{a}"]] = p[idx[f"instrument.t{a}"]] = 0.0
    base = geometry.predict(p, data.readings, data.point)
    w = 1.0 / data.sigma**2
    cb, cm = np.average(base, axis=0, weights=w), np.average(data.xyz, axis=0, weights=w)
    rotation, _ = Rotation.align_vectors(data.xyz - cm, base - cb, weights=w)
    t = cm - rotation.apply(cb)
    for k, a in enumerate("xyz"):
        p[idx[f"instrument.r{a}"]] = rotation.as_rotvec()[k]
        p[idx[f"instrument.t{a}"]] = t[k]
    return p


def _jacobian(f: Any, u0: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """Central differences of f at u0 (columns per entry of u0)."""
    cols = []
    for k in range(len(u0)):
        du = np.zeros_like(u0)
        du[k] = step
        cols.append((f(u0 + du) - f(u0 - du)) / (2.0 * step))
    return np.stack(cols, axis=-1)


def _combination(names: Sequence[str], v: np.ndarray) -> str:
    order = np.argsort(-np.abs(v))
    terms = [f"{v[k]:+.2f} {names[k]}" for k in order if abs(v[k]) >= 0.1 * abs(v[order[0]])][:6]
    return " ".join(terms)


def calibrate(
    description: Description,
    data: Measurements,
    tolerance: float = 0.005,
    max_nfev: int = 200,
    hold: Mapping[str, str] | None = None,
) -> Calibration:
    """Fit the machine to the measured points (module docstring). ``tolerance`` (m): a parameter
    combination the data determine worse than this (1 sigma, an angle as its arc at REACH) is not
    observable and held at the drawing. ``hold``: parameters (by name) held at the drawing anyway,
    each with the reason the report gives (the cylinders' zero offsets for a machine whose nodes
    read its sensors without offsets). Raises CalibrationError (one line) if the data are too few
    or the fit does not converge or leaves the bounds."""
    g = Geometry(description)
    for i, q in enumerate(g.parameters):
        if hold and q.name in hold and not q.held:
            g.parameters[i] = replace(q, held=hold[q.name])
    free = np.array([not p.held for p in g.parameters])
    names = [p.name for p in g.parameters]
    n_data = 3 * len(data.point)
    if n_data < free.sum():
        raise CalibrationError(
            f"{len(set(data.pose))} poses, {len(data.point)} points ({n_data} coordinates) for {free.sum()} "
            f"parameters: too few poses (measure at least {math.ceil(free.sum() / 3)} points)"
        )
    p0 = _placement(g, g.drawing, data)
    wsig = 1.0 / data.sigma[:, None]

    def weighted(p: np.ndarray) -> np.ndarray:
        return ((g.predict(p, data.readings, data.point) - data.xyz) * wsig).ravel()

    def at(u: np.ndarray) -> np.ndarray:  # scaled free coordinates -> parameters
        p = p0.copy()
        p[free] += g.scale[free] * u
        return p

    drawing_residuals = g.predict(p0, data.readings, data.point) - data.xyz
    if not np.all(np.isfinite(drawing_residuals)):
        row = int(np.argmax(~np.all(np.isfinite(drawing_residuals), axis=1)))
        raise CalibrationError(
            f"pose {data.pose[row]!r}: the drawing's linkage does not close at these readings "
            f"({', '.join(f'{v:.6g}' for v in data.readings[row])})"
        )
    J = _jacobian(lambda u: weighted(at(u)), np.zeros(free.sum()))
    _, s, Vt = np.linalg.svd(J, full_matrices=True)
    s = np.concatenate((s, np.zeros(Vt.shape[0] - len(s))))
    weak = (s <= 0.0) | (1.0 / np.maximum(s, 1e-300) > tolerance)
    V_obs, V_null = Vt[~weak].T, Vt[weak].T
    free_names = [n for n, f in zip(names, free, strict=True) if f]

    bound = np.array([q.bound for q in g.parameters])[free] / g.scale[free]
    if V_null.shape[1] == 0:  # everything observable: the parameters themselves, each in its bound
        V_obs, c_bound = np.eye(len(bound)), bound
    else:  # on the observable combinations: a 1 m (scaled) box each, the bounds checked after
        c_bound = np.ones(V_obs.shape[1])

    def residual(c: np.ndarray) -> np.ndarray:
        r = weighted(at(V_obs @ c))
        return np.where(np.isfinite(r), r, 1e6)

    result = least_squares(
        residual,
        np.zeros(V_obs.shape[1]),
        bounds=(-c_bound, c_bound),
        x_scale=1.0,
        ftol=1e-15,
        xtol=1e-15,
        gtol=1e-15,
        max_nfev=max_nfev,
        method="trf",
    )
    if result.status <= 0 or not np.all(np.isfinite(result.fun)) or np.any(np.abs(result.fun) >= 1e6):
        raise CalibrationError(f"the fit did not converge ({result.message}); nothing written")
    if np.any(result.active_mask != 0):  # a bound stops the fit: no geometry near the drawing fits
        k = int(np.flatnonzero(result.active_mask)[0])
        what = free_names[k] if V_null.shape[1] == 0 else _combination(free_names, V_obs[:, k])
        raise CalibrationError(
            f"the fit stopped at the bound of {what} (0.2 m from the drawing): drawing or data wrong; "
            "nothing written"
        )
    u = V_obs @ result.x
    p = at(u)
    moved = np.abs(p - g.drawing)
    over = moved[free] > np.array([q.bound for q in g.parameters])[free] + 1e-12
    if np.any(over):
        k = int(np.flatnonzero(over)[0])
        raise CalibrationError(
            f"the fit moved {free_names[k]} by {moved[free][k]:.3f} from the drawing (bound "
            f"{g.parameters[names.index(free_names[k])].bound}): drawing or data wrong; nothing written"
        )
    Jc = result.jac
    cov_c = np.linalg.pinv(Jc.T @ Jc)
    chi2_per_dof = float(np.sum(result.fun**2) / max(n_data - V_obs.shape[1], 1))
    # Given sigmas are taken as the truth about the instrument (absolute); the default sigma is a
    # guess, so the covariance is scaled by the scatter the residuals show (as scipy's curve_fit
    # does without absolute_sigma).
    variance_scale = 1.0 if data.sigma_given else chi2_per_dof
    std = np.zeros(len(p))
    std[free] = g.scale[free] * np.sqrt(
        variance_scale * np.maximum(np.einsum("ij,jk,ik->i", V_obs, cov_c, V_obs), 0.0)
    )
    held_share = np.ones(len(p))
    held_share[free] = np.linalg.norm(V_null, axis=1) ** 2

    # The exact gauges span a subspace whose SVD basis is arbitrary: turned so that each has its
    # own leading parameter (reduced echelon form, pivots by QR with column pivoting), which
    # makes each one read as a single mechanism (a cylinder's pins turned about their hinge).
    exact = np.flatnonzero(s <= 1e-6 * s[0])
    directions = Vt.copy()
    if len(exact):
        N = Vt[exact].T
        _, _, pivots = qr(N.T, pivoting=True)
        B = N @ np.linalg.inv(N[pivots[: len(exact)]])
        directions[exact] = (B / np.linalg.norm(B, axis=0)).T
    not_observable = []
    for i in np.flatnonzero(weak):
        v = directions[i]
        entry = {
            "combination": _combination(free_names, v),
            "std_if_fitted": None if s[i] <= 1e-6 * s[0] else float(1.0 / s[i]),
            "kind": "gauge (exact)" if s[i] <= 1e-6 * s[0] else "weak",
            "held": "at the drawing",
            "would_determine": _suggest(g, at, v, s[i], data, tolerance),
        }
        not_observable.append(entry)
    held = [{"parameter": q.name, "why": q.held} for q in g.parameters if q.held]
    r = g.predict(p, data.readings, data.point) - data.xyz
    return Calibration(
        geometry=g,
        values=p,
        std=std,
        held_share=held_share,
        not_observable=not_observable,
        held=held,
        residuals=r,
        drawing_residuals=drawing_residuals,
        measurements=data,
        cost={
            "nfev": int(result.nfev),
            "chi2_per_dof": chi2_per_dof,
            "std_scaled_by_chi2": not data.sigma_given,
            "message": result.message,
            "fitted_directions": int(V_obs.shape[1]),
            "held_directions": int(V_null.shape[1]),
        },
    )


def _suggest(
    g: Geometry, at: Any, v: np.ndarray, s: float, data: Measurements, tolerance: float
) -> list[str]:
    """Extra measurements that would bring the combination v under ``tolerance``: a point at the
    same poses, or the measured points at poses with one cylinder at a stroke end."""
    sigma = float(np.median(data.sigma))
    h = 1e-6

    def along(readings: np.ndarray, names: Sequence[str]) -> np.ndarray:
        return (g.predict(at(h * v), readings, names) - g.predict(at(-h * v), readings, names)) / (2 * h)

    poses = {}
    for k, pose in enumerate(data.pose):
        poses.setdefault(pose, data.readings[k])
    readings = np.array(list(poses.values()))
    out = []
    measured = set(data.point)
    for name in g.point_names:
        if name in measured:
            continue
        gain = np.linalg.norm(along(readings, [name] * len(readings))) / sigma
        if 1.0 / math.hypot(s, gain) <= tolerance and np.isfinite(gain):
            out.append(f"measure {name} at the same poses")
    d = g.description
    names = sorted(measured)
    middle = np.median(readings, axis=0)
    for c in d.cylinders:
        ends = np.repeat(middle[None], 2, axis=0)
        ends[:, c.index] = [c.lower, c.upper]
        ends -= g.offsets(g.drawing)
        rows = np.repeat(ends, len(names), axis=0)
        gain = np.linalg.norm(along(rows, names * 2)) / sigma
        if np.isfinite(gain) and 1.0 / math.hypot(s, gain) <= tolerance:
            out.append(f"add poses with {c.name} at both stroke ends, measuring {', '.join(names)}")
    return out or ["no single extra point or pose found; measure more pins"]
