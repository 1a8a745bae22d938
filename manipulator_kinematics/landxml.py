"""LandXML 1.2 TIN surfaces (the format machine-control and civil-design software exchange):
read, bounded and checked, and written (numpy, no rclpy; machine-independent: the excavator's grade
outputs and every machine's avoidance zones use it).

* :func:`read_landxml` reads ``LandXML/Surfaces/Surface/Definition[@surfType="TIN"]`` with its
  ``Pnts/P id="..."`` ("northing easting elevation", LandXML's order, swapped here to x = easting,
  y = northing) and ``Faces/F`` (three point ids; ``i="1"`` marks an invisible face, a hole, which
  is left out). Linear units from ``Units/Metric`` or ``Units/Imperial`` are converted to metres.
* :class:`Tin` finds the triangle vertically below each query point with matplotlib's
  :class:`~matplotlib.tri.TrapezoidMapTriFinder` (a trapezoid-map point location, O(log n) per
  point; benchmarks/bench_design_surface.py: about 3 us for the three points of one state on
  10^5 triangles), and its height above the triangle's plane ``z = a x + b y + c``:
  ``h = z - (a x + b y + c)``, vertical, positive above (material to cut), negative below (fill).
  A point whose vertical line misses every triangle is *outside*: ``inside`` is False there and
  the height NaN, never a number that could be mistaken for a grade.
* :func:`write_tin` and :func:`write_landxml` write one surface.

Everything is in the **site frame** (x = easting, y = northing, z = elevation, metres).
Coordinates of a site are large (UTM northings of 10^6 m): the TIN is held relative to its own
origin (the middle of its bounding box), so the planes' coefficients keep their digits.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
from matplotlib.tri import TrapezoidMapTriFinder, Triangulation
from numpy.typing import ArrayLike

from manipulator_kinematics.param_files import ConfigError, open_input, shown

NAMESPACE = "http://www.landxml.org/schema/LandXML-1.2"


def write_tin(
    path: str | Path,
    vertices: np.ndarray,
    faces: np.ndarray,
    name: str,
    application: str = "manipulator_kinematics",
) -> None:
    """A one-surface LandXML file: ``vertices`` (V, 3) site frame, ``faces`` (F, 3) 0-based."""
    root = ET.Element(
        "LandXML", {"xmlns": NAMESPACE, "version": "1.2", "date": "2026-01-01", "time": "00:00:00"}
    )
    ET.SubElement(
        ET.SubElement(root, "Units"),
        "Metric",
        {
            "areaUnit": "squareMeter",
            "linearUnit": "meter",
            "volumeUnit": "cubicMeter",
            "temperatureUnit": "celsius",
            "pressureUnit": "milliBars",
        },
    )
    ET.SubElement(root, "Application", {"name": application, "version": "1"})
    surface = ET.SubElement(ET.SubElement(root, "Surfaces"), "Surface", {"name": name})
    definition = ET.SubElement(surface, "Definition", {"surfType": "TIN"})
    pnts, tris = ET.SubElement(definition, "Pnts"), ET.SubElement(definition, "Faces")
    for i, (x, y, z) in enumerate(np.asarray(vertices, float).tolist(), start=1):
        ET.SubElement(pnts, "P", {"id": str(i)}).text = f"{y:.6f} {x:.6f} {z:.6f}"
    for a, b, c in (np.asarray(faces) + 1).tolist():
        ET.SubElement(tris, "F").text = f"{a} {b} {c}"
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


#: LandXML linearUnit values -> metres (LandXML 1.2 schema, enumerations metLinear and impLinear).
LINEAR_UNITS = {
    "meter": 1.0,
    "kilometer": 1000.0,
    "centimeter": 0.01,
    "millimeter": 0.001,
    "foot": 0.3048,
    "internationalFoot": 0.3048,
    "USSurveyFoot": 1200.0 / 3937.0,
    "inch": 0.0254,
    "mile": 1609.344,
}


#: Bounds of a design surface, checked before the work they bound: the file's size before it is
#: read; while it is read, its elements (points, faces and all others), before the whole tree is
#: built. A TIN of 10^6 faces took 50 s and 1.9 GB to load (issue 29); 2 x 10^5 faces (13.6 MB of
#: LandXML) took 43 s and 0.8 GB, 10^5 faces 17 s, on 2 cores shared by 8 busy processes, most of it
#: the index (Tin); a site's design surface has far fewer.
MAX_FILE_BYTES = 32 << 20
MAX_FACES = 200_000
MAX_POINTS = 200_000
MAX_ELEMENTS = MAX_FACES + MAX_POINTS + 10_000
#: Largest horizontal distance of a point from the coordinate system's origin (m): 2.5 times the
#: Earth's circumference, beyond any projected grid (UTM northings reach 10^7 m); and largest
#: elevation above or below its datum (m). A coordinate beyond either is no place on a site.
MAX_HORIZONTAL = 1e8
MAX_ELEVATION = 1e5


class SurfaceHeights(NamedTuple):
    """Heights of points above a surface; arrays of the points' batch shape (...,)."""

    height: np.ndarray  # m, vertical, positive above; NaN where not inside
    inside: np.ndarray  # bool: the vertical through the point meets the surface
    triangle: np.ndarray  # index of the triangle below the point, -1 outside


@dataclass(frozen=True)
class Tin:
    """A triangulated irregular network: ``vertices`` (V, 3) site frame, ``faces`` (F, 3) indices."""

    vertices: np.ndarray
    faces: np.ndarray
    name: str = ""
    origin: np.ndarray = field(init=False, repr=False)
    #: (F, 3): a, b, c of each triangle's plane z = a x + b y + c, relative to ``origin``.
    planes: np.ndarray = field(init=False, repr=False)
    _finder: TrapezoidMapTriFinder = field(init=False, repr=False)

    def __post_init__(self) -> None:
        vertices = np.asarray(self.vertices, dtype=float)
        faces = np.asarray(self.faces)
        what = f"surface {shown(self.name)}" if self.name else "surface"
        if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
            raise ValueError(
                f"{what}: expected vertices of shape (V, 3) and faces (F, 3), "
                f"got shapes {vertices.shape} and {faces.shape}"
            )
        if len(faces) == 0:
            raise ConfigError(f"{what}: no (visible) faces")
        if len(faces) > MAX_FACES or len(vertices) > MAX_POINTS:
            raise ConfigError(
                f"{what}: {len(faces)} faces and {len(vertices)} points, more than the "
                f"{MAX_FACES} faces or {MAX_POINTS} points a surface may have"
            )
        if not np.all(np.isfinite(vertices)):
            raise ConfigError(f"{what}: a vertex coordinate is not finite")
        # Before any arithmetic on them: 1e300 overflowed the cross products below.
        far = np.any(np.abs(vertices) > [MAX_HORIZONTAL, MAX_HORIZONTAL, MAX_ELEVATION], axis=1)
        if np.any(far):
            k = int(np.argmax(far))
            raise ConfigError(
                f"{what}: vertex {k} at {vertices[k].tolist()} m is no place on a site "
                f"(|x|, |y| <= {MAX_HORIZONTAL:g} m, |z| <= {MAX_ELEVATION:g} m)"
            )
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise ConfigError(f"{what}: a face refers to a vertex index outside 0..{len(vertices) - 1}")
        faces = faces.astype(np.int32)
        used = np.unique(faces)
        lo, hi = vertices[used, :2].min(axis=0), vertices[used, :2].max(axis=0)
        origin = np.array([*(0.5 * (lo + hi)), 0.0])
        local = vertices - origin
        # The point location needs a valid triangulation (matplotlib: no duplicate points, no
        # degenerate triangles); refuse what would give wrong answers, naming it.
        _, first, counts = np.unique(local[used, :2], axis=0, return_index=True, return_counts=True)
        if np.any(counts > 1):
            shared = vertices[used[first[counts > 1][0]], :2].tolist()
            raise ConfigError(f"{what}: two vertices share x, y {shared}")
        p0, p1, p2 = local[faces[:, 0]], local[faces[:, 1]], local[faces[:, 2]]
        normal = np.cross(p1 - p0, p2 - p0)
        scale = float(np.max(hi - lo)) or 1.0
        flat = np.abs(normal[:, 2]) <= 1e-12 * scale * scale
        if np.any(flat):
            raise ConfigError(f"{what}: face {int(np.argmax(flat))} has no area in plan view (degenerate)")
        _refuse_overlaps(faces, normal[:, 2] > 0.0, what)
        _refuse_islands_inside(local[:, :2], faces, normal[:, 2] > 0.0, what)
        a, b = -normal[:, 0] / normal[:, 2], -normal[:, 1] / normal[:, 2]
        planes = np.column_stack([a, b, p0[:, 2] - a * p0[:, 0] - b * p0[:, 1]])
        try:
            finder = TrapezoidMapTriFinder(Triangulation(local[:, 0], local[:, 1], faces))
        except (RuntimeError, ValueError):  # matplotlib: "Triangulation is invalid"
            raise ConfigError(
                f"{what}: faces overlap in plan view (edges of two faces cross), so a point "
                "would lie on two of them"
            ) from None
        for name, value in (
            ("vertices", vertices),
            ("faces", faces),
            ("origin", origin),
            ("planes", planes),
            ("_finder", finder),
        ):
            object.__setattr__(self, name, value)

    def locate(self, xy: ArrayLike) -> np.ndarray:
        """Index of the triangle below each point ``xy`` (..., 2) (site frame), -1 outside."""
        xy = np.asarray(xy, dtype=float)
        return self._finder(xy[..., 0] - self.origin[0], xy[..., 1] - self.origin[1])

    def heights(self, points: ArrayLike) -> SurfaceHeights:
        """Vertical heights of ``points`` (..., 3) (site frame) above the surface."""
        points = np.asarray(points, dtype=float)
        local = points - self.origin
        triangle = self._finder(local[..., 0], local[..., 1])
        inside = triangle >= 0
        a, b, c = np.moveaxis(self.planes[np.where(inside, triangle, 0)], -1, 0)
        height = local[..., 2] - (a * local[..., 0] + b * local[..., 1] + c)
        return SurfaceHeights(np.where(inside, height, np.nan), inside, triangle)

    def locate_all_triangles(self, xy: ArrayLike) -> np.ndarray:
        """:meth:`locate` without an index: every point against every triangle (barycentric signs).

        The baseline of benchmarks/bench_design_surface.py and the tests' independent check;
        O(points x triangles). A point on a shared edge gets the lowest index of its triangles.
        """
        xy = np.asarray(xy, dtype=float) - self.origin[:2]
        tri = (self.vertices - self.origin)[self.faces][:, :, :2]  # (F, 3, 2)
        p = xy[..., None, :]  # (..., 1, 2)
        sides = []
        for i in range(3):
            start, end = tri[:, i], tri[:, (i + 1) % 3]
            edge, to_p = end - start, p - start
            sides.append(edge[:, 0] * to_p[..., 1] - edge[:, 1] * to_p[..., 0])
        sides = np.stack(sides, axis=-1)  # (..., F, 3)
        hit = np.all(sides >= 0.0, axis=-1) | np.all(sides <= 0.0, axis=-1)
        return np.where(hit.any(axis=-1), np.argmax(hit, axis=-1), -1)


def _refuse_overlaps(faces: np.ndarray, counterclockwise: np.ndarray, what: str) -> None:
    """ConfigError naming two faces on the same side of an edge: turned counterclockwise in plan
    view, the faces of a surface that does not fold over itself use each directed edge once (a
    shared edge in opposite directions), so a duplicate face or one folded over its neighbour
    uses one twice. (Faces that overlap without a shared edge mostly have crossing edges, which
    the trapezoid map refuses; a patch wholly inside another face, sharing no edge, is
    :func:`_refuse_islands_inside`'s.)"""
    turned = np.where(counterclockwise[:, None], faces, faces[:, ::-1]).astype(np.int64)
    edges = np.concatenate([turned[:, [0, 1]], turned[:, [1, 2]], turned[:, [2, 0]]])  # row k: face k % F
    key = edges[:, 0] * (int(edges.max()) + 1) + edges[:, 1]  # one integer per directed edge
    order = np.argsort(key, kind="stable")
    twice = np.flatnonzero(key[order[1:]] == key[order[:-1]])
    if len(twice):
        first, second = order[twice[0]], order[twice[0] + 1]
        raise ConfigError(
            f"{what}: faces {first % len(faces)} and {second % len(faces)} lie on the same "
            f"side of their edge {edges[first].tolist()}: they overlap (a duplicate face or "
            "a fold)"
        )


def _refuse_islands_inside(
    xy: np.ndarray, faces: np.ndarray, counterclockwise: np.ndarray, what: str
) -> None:
    """ConfigError naming a patch of faces that lies wholly inside another face (no edge shared
    or crossed, so neither the edge rule nor the trapezoid map sees it): one vertex of each
    boundary loop (edges used once) is tested against every face it is not a corner of. Loops
    are few (the outline, holes, islands), so this is O(loops x faces)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    turned = np.where(counterclockwise[:, None], faces, faces[:, ::-1]).astype(np.int64)
    edges = np.concatenate([turned[:, [0, 1]], turned[:, [1, 2]], turned[:, [2, 0]]])
    n = int(edges.max()) + 1
    key, reverse = edges[:, 0] * n + edges[:, 1], edges[:, 1] * n + edges[:, 0]
    boundary = edges[~np.isin(key, reverse)]
    graph = coo_matrix((np.ones(len(boundary)), (boundary[:, 0], boundary[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    on_boundary = np.unique(boundary)
    _, first = np.unique(label[on_boundary], return_index=True)
    tri = xy[faces]  # (F, 3, 2)
    for vertex in on_boundary[first]:
        p = xy[vertex]
        sides = np.stack(
            [
                (tri[:, (i + 1) % 3, 0] - tri[:, i, 0]) * (p[1] - tri[:, i, 1])
                - (tri[:, (i + 1) % 3, 1] - tri[:, i, 1]) * (p[0] - tri[:, i, 0])
                for i in range(3)
            ],
            axis=1,
        )
        scale = np.abs(sides).max(axis=1) + 1e-300
        strictly = np.all(sides > 1e-9 * scale[:, None], axis=1) | np.all(
            sides < -1e-9 * scale[:, None], axis=1
        )
        strictly &= ~np.any(faces == vertex, axis=1)
        if strictly.any():
            raise ConfigError(
                f"{what}: vertex {int(vertex)} lies inside face {int(np.argmax(strictly))}: a patch of "
                "faces overlaps another face in plan view"
            )


def read_landxml(path: str | Path, surface: str = "") -> Tin:
    """The TIN named ``surface`` of a LandXML 1.2 file (``""``: the file's only surface).

    ConfigError naming the file and what is wrong: not a regular file or larger than
    MAX_FILE_BYTES, more than MAX_ELEMENTS elements (refused while reading, before the tree is
    whole), not XML, no such surface (the names found are listed), not a TIN, a point or face
    that does not parse, an unknown linear unit, or what :class:`Tin` refuses.
    """
    path = Path(path)
    root = _parse_bounded(path)
    if _local(root.tag) != "LandXML":
        raise ConfigError(f"{path}: the root element is {shown(_local(root.tag))}, not LandXML")
    metres = _linear_unit(root, path)
    surfaces = [s for s in _children(root, "Surfaces") for s in _children(s, "Surface")]
    names = [s.get("name", "") for s in surfaces]
    if surface:
        chosen = [s for s in surfaces if s.get("name", "") == surface]
        if not chosen:
            raise ConfigError(f"{path}: no Surface named {shown(surface)} (surfaces: {shown(names)})")
    elif len(surfaces) != 1:
        raise ConfigError(f"{path}: {len(surfaces)} surfaces {shown(names)}: name the one to use")
    else:
        chosen = surfaces
    element = chosen[0]
    name = element.get("name", "")
    definitions = _children(element, "Definition")
    if not definitions or definitions[0].get("surfType", "").upper() != "TIN":
        kind = definitions[0].get("surfType") if definitions else None
        raise ConfigError(
            f'{path}: surface {shown(name)} has no Definition with surfType="TIN" (got {shown(kind)})'
        )
    definition = definitions[0]
    ids, coordinates = [], []
    for p in (p for pnts in _children(definition, "Pnts") for p in _children(pnts, "P")):
        ids.append(p.get("id", ""))
        coordinates.append(_numbers(p.text, 3, f"{path}: surface {shown(name)} point id={shown(ids[-1])}"))
    index = {pid: i for i, pid in enumerate(ids)}
    if len(index) != len(ids):
        raise ConfigError(f"{path}: surface {shown(name)}: point ids are not unique")
    faces = []
    for f in (f for fs in _children(definition, "Faces") for f in _children(fs, "F")):
        if f.get("i", "0") == "1":  # invisible: a hole in the surface
            continue
        corners = (f.text or "").split()
        missing = [c for c in corners if c not in index]
        if len(corners) != 3 or missing:
            raise ConfigError(
                f"{path}: surface {shown(name)}: face {shown(f.text)} is not three point ids "
                f"of its Pnts{f' (unknown: {shown(missing)})' if missing else ''}"
            )
        faces.append([index[c] for c in corners])
    if not coordinates or not faces:
        raise ConfigError(f"{path}: surface {shown(name)} has no points or no faces")
    northing_easting_elevation = np.array(coordinates) * metres
    vertices = northing_easting_elevation[:, [1, 0, 2]]
    try:
        return Tin(vertices, np.array(faces), name)
    except ConfigError as error:
        raise ConfigError(f"{path}: {error}") from None


def write_landxml(path: str | Path, tin: Tin, application: str = "manipulator_kinematics") -> None:
    """``tin`` as a LandXML 1.2 file (metres, points "northing easting elevation")."""
    write_tin(path, tin.vertices, tin.faces, tin.name or "design", application)


def _parse_bounded(path: Path) -> ET.Element:
    """The root element of the XML file ``path``, read within MAX_FILE_BYTES and MAX_ELEMENTS."""
    with open_input(path, MAX_FILE_BYTES) as stream:
        try:
            events = ET.iterparse(stream, events=("start",))
            _, root = next(events)
            for count, _ in enumerate(events, start=2):
                if count > MAX_ELEMENTS:
                    raise ConfigError(
                        f"{path}: more than the {MAX_ELEMENTS} XML elements a design "
                        f"surface file may have ({MAX_FACES} faces, {MAX_POINTS} points)"
                    )
        except (ET.ParseError, StopIteration) as error:
            raise ConfigError(f"{path}: cannot read a LandXML file: {error or 'empty'}") from None
    return root


def _local(tag: str) -> str:
    """An element's name without its namespace (files differ in how they declare LandXML's)."""
    return tag.rsplit("}", 1)[-1]


def _children(element: ET.Element, name: str) -> list[ET.Element]:
    return [child for child in element if _local(child.tag) == name]


def _linear_unit(root: ET.Element, path: Path) -> float:
    for units in _children(root, "Units"):
        for system in units:
            unit = system.get("linearUnit")
            if unit is not None:
                if unit not in LINEAR_UNITS:
                    raise ConfigError(
                        f"{path}: linearUnit {shown(unit)} is not one of {sorted(LINEAR_UNITS)}"
                    )
                return LINEAR_UNITS[unit]
    return 1.0  # LandXML without Units: metres, as every metric exporter writes


def _numbers(text: str | None, count: int, what: str) -> list[float]:
    try:
        values = [float(v) for v in (text or "").split()]
    except ValueError:
        values = []
    if len(values) != count or not all(np.isfinite(values)):
        raise ConfigError(f"{what}: expected {count} numbers, got {shown(text)}")
    return values
