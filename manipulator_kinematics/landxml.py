"""LandXML 1.2 TIN surfaces written (the format machine-control and civil-design software exchange).

Points are written as LandXML orders them, "northing easting elevation", from site-frame x =
easting, y = northing, z = elevation (metres). Reading a design TIN, with its bounds and checks,
is the excavator's :mod:`excavator_kinematics.grade.design_surface`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

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
