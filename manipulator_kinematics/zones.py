"""Avoidance zones: where no monitored point of a machine may go, and how fast it may approach.

A zone file (YAML, read by the package's one safe loader) names zones under ``zones:``, each with
a ``kind``, a ``frame`` (``base``: base_link; ``site``: x easting, y northing, z up, placed by the
machine's site pose as the grade outputs are) and a ``margin`` (m) kept from its boundary:

* ``ceiling`` (``height``): nothing above it (a power line); ``floor`` (``height``): nothing below;
* ``wall``: a vertical half-plane through ``point`` [x, y] with the horizontal ``normal`` [nx, ny]
  pointing into the forbidden side (a trench edge, a road);
* ``box``: the axis-aligned box ``min`` [x, y, z] .. ``max`` (a building, a parked truck);
* ``sector``: swing angles ``from`` .. ``to`` (rad, counter-clockwise from base x, base frame
  only): the points' bearings about the swing axis (the machine's own tail side, a road);
* ``surface``: a LandXML TIN (``file``, ``surface``: its name, "" = the only one) with ``side:
  below`` (nothing below it: a buried service's protective surface) or ``above``.

**Clearance** of a point is its signed distance from the zone grown by the margin: positive
outside, zero on the boundary plus margin, negative inside; with it ``g``, its gradient (the
direction in which it grows: vertical for ceilings and floors, the wall's normal, the box's
outward direction, the tangent of the swing for sectors, at the point's radius; for surfaces,
whose clearance is the vertical height above or below the TIN, (-a, -b, 1) of the triangle's
plane z = a x + b y + c, turned for ``side: above``). A TIN zone covers its footprint only: a point
outside it (clearance inf) is not watched.

**Speed scale.** A command moves each point along a path p + v sigma + a sigma^2 / 2, where
sigma is time at the full command, ``v`` the point's velocity and ``a`` its acceleration at
constant actuator rates (how the path curves: a point swung about a joint moves on a circle); its
clearance along the path is c - u sigma - w sigma^2 / 2 with u = -g . v and w = -g . a. Until this
command takes over, the one in force goes on for ``delay`` (the state's way in, the command's way
out, the actuators' lag) at its own approach speed u_f: ``room`` = c - max(u_f, 0) delay. Scaled
by ``s``, the command covers sigma = ``s dt`` until the next command can react (``dt``, the
control period) and ``s^2 T / 2`` while stopping, where ``T = max_i |Ddot_i| / a_i`` is the time
the actuators need to stop the unscaled command at their deceleration limits ``a_i`` (every
actuator slows in proportion, so the motion keeps its path and the point decelerates along it).
The largest ``s`` in [0, 1] with ``s dt + s^2 T / 2 <= reach`` for every (point, zone) pair, where
``reach`` is the first sigma at which the clearance along the path reaches 0 (none: a pair moving
away or along on a path that does not curve into the zone never limits it), is the command's
scale. A pair with no room left stops it if it approaches (u > 0) and never limits it if it moves
out, so a machine inside a zone may only move out. The velocity IK applies this one factor to its
whole command: it slows approaching a zone and stops at it, never bent.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, Protocol

import numpy as np

from manipulator_kinematics.compiled import Kernel
from manipulator_kinematics.param_files import ConfigError, read_document
from manipulator_kinematics.schema import Number, Numbers, Schema, Text, require, validate
from manipulator_kinematics.zone_layout import KIND, WIDTH, ZONE, check_compiled

KINDS = ("ceiling", "floor", "wall", "box", "sector", "surface")
FRAMES = ("base", "site")
#: Zones in one file at the most (each adds its pairs to every command's check).
MAX_ZONES = 64

_COMMON: Schema = {
    "kind": Text(choices=KINDS, doc="what the zone is"),
    "frame": Text(choices=FRAMES, default="base", doc="base (base_link) or site"),
    "margin": Number(min=0.0, max=100.0, unit="m", default=0.0, doc="distance kept from the boundary"),
}
_COORD = Number(min=-1e7, max=1e7, unit="m")
SCHEMAS: dict[str, Schema] = {
    "ceiling": {**_COMMON, "height": Number(min=-1e4, max=1e4, unit="m")},
    "floor": {**_COMMON, "height": Number(min=-1e4, max=1e4, unit="m")},
    "wall": {**_COMMON, "point": Numbers(2, _COORD), "normal": Numbers(2, Number(min=-1e3, max=1e3))},
    "box": {**_COMMON, "min": Numbers(3, _COORD), "max": Numbers(3, _COORD)},
    "sector": {
        **_COMMON,
        "from": Number(min=-2 * math.pi, max=2 * math.pi, unit="rad"),
        "to": Number(min=-2 * math.pi, max=2 * math.pi, unit="rad"),
    },
    "surface": {
        **_COMMON,
        "file": Text(empty=False),
        "surface": Text(default=""),
        "side": Text(choices=("below", "above")),
    },
}


class Surface(Protocol):
    """A TIN (:class:`manipulator_kinematics.landxml.Tin`): ``locate(xy (..., 2))`` gives the
    index of the triangle below each point (-1 outside), ``planes`` (T, 3) each triangle's
    [a, b, c] of z - origin_z = a (x - origin_x) + b (y - origin_y) + c."""

    planes: Any
    origin: Any

    def locate(self, xy: Any) -> Any: ...


@dataclass(frozen=True)
class Zone:
    """One zone (module docstring); ``values`` as validated, ``surface`` for ``kind: surface``."""

    name: str
    kind: str
    frame: str
    margin: float
    values: Mapping[str, Any]
    surface: Surface | None = None

    def clearance(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Clearance (..., P) of points (..., P, 3) in the zone's frame, and its gradient g
        (..., P, 3) (unit but for sloped surfaces, zero where it has none)."""
        c, g = _Kind.of([self]).clearance(np.asarray(points, dtype=float))
        return c[..., 0], g[..., 0, :]

    def half_space(self) -> tuple[np.ndarray, float]:
        """(n, b) of a ceiling, floor or wall: clearance n . p + b with n the unit gradient."""
        v, m = self.values, self.margin
        if self.kind == "wall":
            inward = np.asarray(v["normal"], float) / np.linalg.norm(v["normal"])
            return np.array([-inward[0], -inward[1], 0.0]), float(np.dot(v["point"], inward)) - m
        up = 1.0 if self.kind == "floor" else -1.0
        return np.array([0.0, 0.0, up]), -up * v["height"] - m


#: Zone kinds that are evaluated together, as one array operation over all zones of the kind.
_PLANES = ("ceiling", "floor", "wall")


@dataclass(frozen=True)
class _Kind:
    """Zones of one kind (planes: ceilings, floors and walls together) as arrays, evaluated at
    once: clearances (..., P, K) and gradients (..., P, K, 3) for points (..., P, 3)."""

    kind: str
    arrays: tuple[Any, ...]
    zones: tuple[Zone, ...]

    @staticmethod
    def of(zones: Sequence[Zone]) -> _Kind:
        kind = "plane" if zones[0].kind in _PLANES else zones[0].kind
        margins = np.array([z.margin for z in zones])
        if kind == "plane":
            normals, offsets = zip(*(z.half_space() for z in zones), strict=True)
            arrays: tuple[Any, ...] = (np.array(normals), np.array(offsets))
        elif kind == "box":
            lo = np.array([z.values["min"] for z in zones], float)
            hi = np.array([z.values["max"] for z in zones], float)
            arrays = (0.5 * (lo + hi), 0.5 * (hi - lo), margins)
        elif kind == "sector":
            start = np.array([z.values["from"] for z in zones], float)
            arrays = (
                start,
                np.mod(np.array([z.values["to"] for z in zones], float) - start, 2 * np.pi),
                margins,
            )
        else:
            arrays = ()
        return _Kind(kind, arrays, tuple(zones))

    def approach(self, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, ...]:
        """Clearances (P, K) of points p (P, 3), their approach speeds u = -g . v and
        accelerations w = -g . a (P, K)."""
        if self.kind == "plane":
            normals, offsets = self.arrays
            return p @ normals.T + offsets, -(v @ normals.T), -(a @ normals.T)
        c, g = self.clearance(p)
        return c, -np.einsum("pzk,pk->pz", g, v), -np.einsum("pzk,pk->pz", g, a)

    def clearance(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.kind == "plane":
            normals, offsets = self.arrays
            c = p @ normals.T + offsets
            return c, np.broadcast_to(normals, c.shape + (3,))
        if self.kind == "box":
            return _boxes(p, *self.arrays)
        if self.kind == "sector":
            return _sectors(p, *self.arrays)
        out = [_surface(p, z) for z in self.zones]
        return np.stack([c for c, _ in out], axis=-1), np.stack([g for _, g in out], axis=-2)


def _boxes(p: np.ndarray, centre: np.ndarray, half: np.ndarray, margin: np.ndarray) -> tuple[np.ndarray, ...]:
    """Signed distance from axis-aligned boxes (K, 3) less their margins, and its gradient."""
    d = p[..., None, :] - centre
    q = np.abs(d) - half
    outside = np.maximum(q, 0.0)
    distance = np.linalg.norm(outside, axis=-1)
    inside = np.minimum(np.max(q, axis=-1), 0.0)
    out_g = outside * np.sign(d) / np.where(distance > 0, distance, 1.0)[..., None]
    axis = np.argmax(q, axis=-1)
    in_g = np.sign(np.take_along_axis(d, axis[..., None], -1)) * (np.arange(3) == axis[..., None])
    return distance + inside - margin, np.where((distance > 0)[..., None], out_g, in_g)


def _sectors(
    p: np.ndarray, start: np.ndarray, width: np.ndarray, margin: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Clearance from swing sectors [start, start + width] (K,) (ccw), as arc length at each
    point's radius, and its gradient (the swing tangent: a radial motion never crosses an edge)."""
    r = np.hypot(p[..., 0], p[..., 1])[..., None]
    bearing = np.arctan2(p[..., 1], p[..., 0])[..., None]
    into = np.mod(bearing - start, 2 * np.pi)  # ccw angle from the sector's start
    inside = into <= width
    past_end = into - width  # ccw beyond the end
    before_start = 2 * np.pi - into  # cw before the start
    nearer_end = np.where(inside, width - into < into, past_end < before_start)
    angle = np.where(inside, -np.minimum(into, width - into), np.minimum(past_end, before_start))
    tangent = np.stack((-np.sin(bearing), np.cos(bearing), np.zeros_like(bearing)), axis=-1)
    # Away from the sector: ccw past its end, cw before its start (and the same way out from inside).
    g = np.where(nearer_end[..., None], tangent, -tangent) * (r > 1e-9)[..., None]
    return np.where(r > 1e-9, r * angle - margin, np.inf), g


def _surface(p: np.ndarray, zone: Zone) -> tuple[np.ndarray, np.ndarray]:
    """Vertical clearance from a TIN (..., P) and its gradient (..., P, 3); inf off its footprint."""
    surface = zone.surface
    assert surface is not None
    sign = 1.0 if zone.values["side"] == "below" else -1.0
    triangle = np.asarray(surface.locate(p[..., :2]))
    inside = triangle >= 0
    plane = surface.planes[np.maximum(triangle, 0)]  # (..., 3) [a, b, c]
    local = p - surface.origin
    # The clearance is a vertical height, h = z - (a x + b y + c): its gradient is (-a, -b, 1),
    # so a point moving level toward rising ground approaches the surface too.
    ones = np.ones(p.shape[:-1] + (1,))
    h = local[..., 2] - np.sum(plane * np.concatenate((local[..., :2], ones), axis=-1), axis=-1)
    g = np.concatenate((-sign * plane[..., :2], sign * ones), axis=-1) * inside[..., None]
    return np.where(inside, sign * h - zone.margin, np.inf), g


def load_zones(path: str | Path, read_surface: Callable[[str, str], Surface] | None = None) -> list[Zone]:
    """The zones of a zone file (module docstring), in file order; ConfigError naming the key
    (``zones.<name>.<key>``) for anything malformed. ``read_surface(file, name)`` reads a TIN
    (a relative ``file`` is relative to the zone file); ``surface`` zones need it."""
    path = Path(path)
    document = read_document(path)
    require(
        isinstance(document, Mapping) and set(document) == {"zones"},
        "zones",
        f"{path}: expected one top-level key 'zones' (a mapping of zone names to zones)",
    )
    entries = document["zones"]
    require(isinstance(entries, Mapping) and entries, "zones", "expected a mapping of zone names to zones")
    require(len(entries) <= MAX_ZONES, "zones", f"{len(entries)} zones; at most {MAX_ZONES}")
    zones = []
    for name, entry in entries.items():
        key = f"zones.{name}"
        require(isinstance(entry, Mapping) and "kind" in entry, key, "expected a mapping with a 'kind'")
        kind = entry["kind"]
        require(kind in SCHEMAS, f"{key}.kind", f"expected one of {', '.join(KINDS)}, got {kind!r}")
        values = validate(entry, SCHEMAS[kind], key)
        surface = None
        if kind == "wall":
            require(math.hypot(*values["normal"]) > 1e-9, f"{key}.normal", "must not be zero")
        elif kind == "box":
            require(
                all(a < b for a, b in zip(values["min"], values["max"], strict=True)),
                f"{key}.max",
                "every coordinate must be above min's",
            )
        elif kind == "sector":
            require(values["frame"] == "base", f"{key}.frame", "a swing sector is in the base frame")
            require(
                np.mod(values["to"] - values["from"], 2 * np.pi) > 0.0,
                f"{key}.to",
                "must differ from 'from' (the sector runs counter-clockwise from 'from' to 'to')",
            )
        elif kind == "surface":
            require(read_surface is not None, key, "surface zones are not supported by this machine")
            file = Path(values["file"])
            file = file if file.is_absolute() else path.parent / file
            try:
                surface = read_surface(str(file), values["surface"])  # type: ignore[misc]
            except (OSError, ValueError) as error:
                raise ConfigError(f"{key}.file: {' '.join(str(error).split())}") from None
        zones.append(Zone(str(name), kind, values["frame"], values["margin"], values, surface))
    return zones


@dataclass(frozen=True)
class Check:
    """One command checked: ``scale`` in [0, 1], the limiting zone and point (None where no zone
    limits it), and per zone the smallest clearance and the point that has it."""

    scale: float
    zone: str | None
    point: str | None
    clearance: dict[str, tuple[float, str]]
    #: Per point and zone (P, K, file order) the approach speed u = -g . v at the full command.
    approach: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def violated(self) -> list[str]:
        """Zones some monitored point is inside (clearance < 0)."""
        return [name for name, (c, _) in self.clearance.items() if c < 0.0]


def scale_for(
    clearance: np.ndarray,
    approach: np.ndarray,
    stop_time: float,
    period: float,
    curving: np.ndarray | float = 0.0,
    in_flight: np.ndarray | float = 0.0,
    delay: float = 0.0,
) -> np.ndarray:
    """Largest scale s in [0, 1] per pair (module docstring, "Speed scale"): with ``room`` = c -
    max(u_f, 0) ``delay`` (``in_flight`` u_f), the first path parameter ``reach`` at which
    room - u sigma - w sigma^2 / 2 = 0 (``curving`` w), and s sigma_H + s^2 T / 2 <= reach. 1 where
    the path never reaches the zone (u <= 0 and w <= 0, or it curves away first), 0 where the
    pair approaches (u > 0) with no room left."""
    c, u, w, u_f = np.broadcast_arrays(
        *(np.asarray(x, float) for x in (clearance, approach, curving, in_flight))
    )
    room = c - np.maximum(u_f, 0.0) * delay
    # The smaller root of w s^2 / 2 + u s = room as 2 room / (u + sqrt(u^2 + 2 w room)): no
    # division by w (0 on a straight path), and the denominator is > 0 wherever it reaches. A
    # pair with infinite room (off a TIN) has u = w = 0: NaN here, never reaching.
    with np.errstate(invalid="ignore", divide="ignore"):
        disc = u * u + 2.0 * w * np.maximum(room, 0.0)
        reaches = (room > 0.0) & ~((w <= 0.0) & (u <= 0.0)) & (disc >= 0.0)
        reach = np.where(reaches, 2.0 * room / (u + np.sqrt(np.maximum(disc, 0.0))), 0.0)
        # s period + s^2 T / 2 = reach, the same way.
        s = np.where(
            reaches, 2.0 * reach / (period + np.sqrt(period * period + 2.0 * stop_time * reach)), 1.0
        )
    s = np.where((room <= 0.0) & (u > 0.0), 0.0, s)
    return np.minimum(s, 1.0)


#: Order of the kinds' columns within a frame on the numpy path: planes, boxes, sectors, then TINs.
_KIND_ORDER = ("plane", "box", "sector", "surface")


def _warm(kernel: ModuleType) -> None:
    """Refuse a kernel compiled for another zone layout, then run it once (numba loads or compiles
    it) on one zone of each kind, without and with a site pose, and let it take only those types:
    arguments of others (a list, a strided view, integers) raise TypeError and the check takes
    the numpy path instead of compiling for seconds in a command."""
    check_compiled(kernel)
    tin = _Tin(np.array([[0.0, 0.0, 1.0]]), np.zeros(3), np.array([0, -1], np.int32))
    monitor = Monitor(
        [
            Zone("c", "ceiling", "base", 0.1, {"height": 3.0}),
            Zone("b", "box", "site", 0.1, {"min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 1.0]}),
            Zone("s", "sector", "base", 0.1, {"from": 0.5, "to": 1.0}),
            Zone("t", "surface", "base", 0.1, {"side": "below"}, tin),
        ],
        ["p", "q"],
    )
    p = np.ones((2, 3))
    for site in (None, (np.eye(3), np.zeros(3))):
        monitor.compiled(kernel, p, p, p, 0.3, 0.05, site, np.zeros((2, 4)), 0.02)
    kernel.check.disable_compile()
    kernel.layout_signature.disable_compile()


#: The compiled check (:mod:`manipulator_kinematics.zone_kernel`), see manipulator_kinematics.compiled.
KERNEL = Kernel("manipulator_kinematics.zone_kernel", _warm)


class Monitor:
    """The zones of a machine and its monitored points (by name), checked per command by the
    compiled kernel (:mod:`zone_kernel`: every kind in one call, a TIN's point location by
    matplotlib before it), or until it is loaded (or with ``MK_COMPILED=0``) in numpy, every zone
    of a kind in one array operation."""

    def __init__(self, zones: Sequence[Zone], points: Sequence[str]) -> None:
        self.zones, self.points = list(zones), list(points)
        self._names = [z.name for z in self.zones]
        # Per frame: the kinds' batches in _KIND_ORDER (the numpy path); where its columns go in
        # the zones' order.
        self._frames: dict[str, list[_Kind]] = {}
        for frame in FRAMES:
            groups: dict[str, list[Zone]] = {}
            for z in self.zones:
                if z.frame == frame:
                    groups.setdefault("plane" if z.kind in _PLANES else z.kind, []).append(z)
            if groups:
                self._frames[frame] = [_Kind.of(groups[k]) for k in _KIND_ORDER if k in groups]
        order = [z.name for kinds in self._frames.values() for k in kinds for z in k.zones]
        self._order = np.array([order.index(z.name) for z in self.zones], dtype=int)
        self._reordered = bool(np.any(self._order != np.arange(len(self.zones))))
        self._site = np.array([z.frame == "site" for z in self.zones], dtype=bool)
        # The kernel's: the zone table (zone_layout), every TIN's planes one after the other, the
        # TIN zones (with their row in the located-triangle table), no site pose, no command in force.
        self._table, self._planes, self._tins = _packed(self.zones)
        self._no_site = np.zeros((4, 3))
        self._no_flight = np.zeros((len(self.points), len(self.zones)))
        self._columns = np.arange(len(self.zones))

    def check(
        self,
        positions: np.ndarray,
        velocities: np.ndarray,
        stop_time: float,
        period: float,
        site: tuple[np.ndarray, np.ndarray] | None = None,
        compiled: bool = True,
        accelerations: np.ndarray | None = None,
        in_flight: np.ndarray | None = None,
        delay: float = 0.0,
    ) -> Check:
        """``positions``, ``velocities`` (P, 3) of the monitored points in the base frame (the
        velocities at full command) and their ``accelerations`` along its path (P, 3, the
        second derivative at constant actuator rates; None: a straight path); ``stop_time`` T
        and ``period`` dt; ``in_flight`` (P, K, zones in file order) the approach speeds of the
        command still in force for ``delay`` s (the last check's ``approach`` times its scale;
        module docstring). ``site`` = (R, t) with p_site = R p + t, needed by site-frame zones
        (without it they are reported at clearance -inf and stop every command: no pose, no
        motion toward them). ``compiled`` false: the numpy path even where the kernel is loaded
        (tests compare them)."""
        p, v = np.ascontiguousarray(positions, float), np.ascontiguousarray(velocities, float)
        a = np.zeros_like(p) if accelerations is None else np.ascontiguousarray(accelerations, float)
        kernel = (KERNEL.ready or KERNEL.get()) if compiled else None
        if kernel is not None and len(p) == len(self.points):
            try:
                return self.compiled(kernel, p, v, a, stop_time, period, site, in_flight, delay)
            except TypeError:  # arguments of types the kernel does not take (_warm): numpy's
                pass
        c, u, s = self._numpy(p, v, a, stop_time, period, site, in_flight, delay)
        j, i = np.unravel_index(int(np.argmin(s)), s.shape)
        nearest = np.argmin(c, axis=0)
        return self._verdict(c, u, s, nearest, c[nearest, self._columns], int(j), int(i), site)

    def compiled(
        self,
        kernel: ModuleType,
        p: np.ndarray,
        v: np.ndarray,
        a: np.ndarray,
        stop_time: float,
        period: float,
        site: tuple[np.ndarray, np.ndarray] | None,
        in_flight: np.ndarray | None,
        delay: float,
    ) -> Check:
        """:meth:`check` by the loaded ``kernel`` (:mod:`zone_kernel`: one call), the points (P,
        3) C-contiguous float arrays; TypeError for arguments it does not take."""
        n, k = p.shape[0], len(self.zones)
        c, u, s = np.empty((n, k)), np.empty((n, k)), np.empty((n, k))
        nearest, least = np.empty(k, dtype=np.int64), np.empty(k)
        pose = self._no_site if site is None else np.vstack((site[0], site[1]), dtype=float)
        u_f = self._no_flight if in_flight is None else np.asarray(in_flight, dtype=float)
        if u_f.shape != c.shape or p.shape != (n, 3) or v.shape != p.shape or a.shape != p.shape:
            # The kernel reads (P, 3) and (P, K) without bounds checks; the numpy path broadcasts
            # what it can and says what it cannot.
            raise TypeError(f"shapes {p.shape}, {v.shape}, {a.shape}, {u_f.shape}: not the kernel's")
        limiting = kernel.check(
            p,
            v,
            a,
            self._table,
            self._planes,
            self._locate(p, pose, site is not None),
            pose,
            site is not None,
            u_f,
            float(delay),
            float(stop_time),
            float(period),
            c,
            u,
            s,
            nearest,
            least,
        )
        return self._verdict(c, u, s, nearest, least, limiting // k, limiting % k, site)

    def _locate(self, p: np.ndarray, pose: np.ndarray, posed: bool) -> np.ndarray:
        """The located-triangle table (TINs, P) of points p (base frame) for the kernel: each TIN's
        triangle under each point in the TIN's frame (-1 off it; a site-frame TIN without a site
        pose is not read)."""
        rows = []
        for zone in self._tins:
            tin = zone.surface
            assert tin is not None
            if zone.frame == "base":
                rows.append(tin.locate(p[:, :2]))
            elif posed:
                rows.append(tin.locate(p @ pose[:2].T + pose[3, :2]))  # the site frame's x, y
            else:
                rows.append(np.full(len(p), -1))
        if len(rows) == 1 and rows[0].dtype == np.int32:  # matplotlib's: no copy
            return rows[0].reshape(1, -1)
        return np.array(rows, dtype=np.int32).reshape(len(rows), len(p))

    def _numpy(
        self,
        p: np.ndarray,
        v: np.ndarray,
        a: np.ndarray,
        stop_time: float,
        period: float,
        site: tuple[np.ndarray, np.ndarray] | None,
        in_flight: np.ndarray | None,
        delay: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Clearances, approach speeds and scales (P, K, zones in file order) in numpy, every zone
        of a kind in one array operation (the reference of the kernel)."""
        cs, us, ws = [], [], []
        for frame, kinds in self._frames.items():
            if frame == "site":
                if site is None:
                    n = sum(len(k.zones) for k in kinds)
                    cs.append(np.full((len(p), n), -np.inf))
                    us.append(np.zeros((len(p), n)))
                    ws.append(np.zeros((len(p), n)))
                    continue
                R = np.asarray(site[0], float)
                zp, zv, za = p @ R.T + site[1], v @ R.T, a @ R.T
            else:
                zp, zv, za = p, v, a
            parts = [k.approach(zp, zv, za) for k in kinds]
            for out, i in ((cs, 0), (us, 1), (ws, 2)):
                out.append(np.concatenate([part[i] for part in parts], axis=1))
        c, u, w = (np.concatenate(x, axis=1) for x in (cs, us, ws))
        if self._reordered:
            c, u, w = c[:, self._order], u[:, self._order], w[:, self._order]
        u_f = np.zeros_like(c) if in_flight is None else np.asarray(in_flight, float)
        s = scale_for(c, u, stop_time, period, w, u_f, delay)
        if site is None and "site" in self._frames:
            s[:, self._site] = 0.0  # no pose: no motion at all
        return c, u, s

    def _verdict(
        self,
        c: np.ndarray,
        u: np.ndarray,
        s: np.ndarray,
        nearest: np.ndarray,
        least: np.ndarray,
        j: int,
        i: int,
        site: tuple[np.ndarray, np.ndarray] | None,
    ) -> Check:
        """The Check of a command's clearances, approach speeds and scales (P, K), each zone's
        nearest point ``nearest`` (K,) and its clearance ``least`` (K,), and the pair (point j,
        zone i) of the smallest scale."""
        points = self.points
        clearance = {
            name: (value, points[k] if math.isfinite(value) else "")
            for name, k, value in zip(self._names, nearest.tolist(), least.tolist(), strict=True)
        }
        if s[j, i] >= 1.0:
            return Check(1.0, None, None, clearance, u)
        lost = site is None and self.zones[i].frame == "site"
        return Check(float(s[j, i]), self._names[i], None if lost else points[j], clearance, u)


@dataclass(frozen=True)
class _Tin:
    """A one-triangle stand-in for a TIN (the kernel's warm-up): ``locate`` gives ``triangles``."""

    planes: np.ndarray
    origin: np.ndarray
    triangles: np.ndarray

    def locate(self, xy: Any) -> np.ndarray:
        return self.triangles


def _packed(zones: Sequence[Zone]) -> tuple[np.ndarray, np.ndarray, list[Zone]]:
    """The kernel's zone table (zone_layout), every TIN's planes one after the other, and the TIN
    zones in the order of their rows in the located-triangle table."""
    table = np.zeros((len(zones), WIDTH))
    planes, tins, first = [np.zeros((0, 3))], [], 0
    for row, zone in zip(table, zones, strict=True):
        row[ZONE.site] = zone.frame == "site"
        row[ZONE.margin] = zone.margin
        kind = "plane" if zone.kind in _PLANES else zone.kind
        row[ZONE.kind] = getattr(KIND, kind)
        v = zone.values
        if kind == "plane":
            normal, row[ZONE.offset] = zone.half_space()
            row[ZONE.normal : ZONE.normal + 3] = normal
        elif kind == "box":
            lo, hi = np.asarray(v["min"], float), np.asarray(v["max"], float)
            row[ZONE.centre : ZONE.centre + 3] = 0.5 * (lo + hi)
            row[ZONE.half : ZONE.half + 3] = 0.5 * (hi - lo)
        elif kind == "sector":
            row[ZONE.start] = v["from"]
            row[ZONE.width] = np.mod(v["to"] - v["from"], 2 * np.pi)
        else:
            tin = zone.surface
            assert tin is not None
            row[ZONE.origin : ZONE.origin + 3] = tin.origin
            row[ZONE.sign] = 1.0 if v["side"] == "below" else -1.0
            row[ZONE.tin], row[ZONE.first] = len(tins), first
            tins.append(zone)
            planes.append(np.asarray(tin.planes, float))
            first += len(tin.planes)
    return table, np.ascontiguousarray(np.concatenate(planes)), tins


def stop_time(rates: np.ndarray, decelerations: np.ndarray) -> float:
    """T = max_i |Ddot_i| / a_i: how long the actuators need to stop a command at their limits."""
    times = np.abs(np.asarray(rates, float)) / np.asarray(decelerations, float)
    return float(times.max()) if times.size else 0.0  # the method: a fifth of np.max's cost


__all__ = ["KINDS", "Check", "Monitor", "Zone", "load_zones", "scale_for", "stop_time"]
