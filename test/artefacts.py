"""Comparisons of shipped artefacts (URDFs, golden bags) with fresh generations that hold on any
machine: structure and text exactly, numbers within a tolerance. The last bit of a computed
value differs between CPUs (numpy dispatches SIMD code by the features it finds), so a test
never compares computed numbers as text or bits across machines."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from manipulator_kinematics.bag.reader import BagReader

#: Largest difference of a number in a shipped artefact and a fresh one (m, rad, m/s, ...).
TOLERANCE = 1e-12


def _numbers(text: str) -> np.ndarray | None:
    try:
        return np.array([float(v) for v in text.split()]) if text.split() else None
    except ValueError:
        return None


def _tree(text: str) -> ET.Element:
    return ET.fromstring(text, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))


def xml_differences(shipped: str, fresh: str, atol: float = TOLERANCE) -> list[str]:
    """Where two XML documents differ: tags, attribute names, order of elements and non-numeric
    text exactly; an attribute of numbers (space separated) only by more than ``atol``."""
    found: list[str] = []

    def walk(a: ET.Element, b: ET.Element, where: str) -> None:
        if a.tag != b.tag or sorted(a.attrib) != sorted(b.attrib):
            found.append(f"{where}: <{a.tag} {sorted(a.attrib)}> vs <{b.tag} {sorted(b.attrib)}>")
            return
        for key, value in a.attrib.items():
            x, y = _numbers(value), _numbers(b.attrib[key])
            if x is not None and y is not None and x.shape == y.shape:
                if not np.all(np.abs(x - y) <= atol):
                    found.append(f"{where}@{key}: {value!r} vs {b.attrib[key]!r}")
            elif value != b.attrib[key]:
                found.append(f"{where}@{key}: {value!r} vs {b.attrib[key]!r}")
        if (a.text or "").strip() != (b.text or "").strip():
            found.append(f"{where}: text {a.text!r} vs {b.text!r}")
        if len(a) != len(b):
            found.append(f"{where}: {len(a)} vs {len(b)} children")
            return
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            name = x.get("name") if isinstance(x.tag, str) else None
            walk(x, y, f"{where}/{x.tag if isinstance(x.tag, str) else 'comment'}[{name or k}]")

    walk(_tree(shipped), _tree(fresh), "robot")
    return found


def bag_differences(shipped: Path, fresh: Path, atol: float = TOLERANCE) -> list[str]:
    """Where two bags differ: topics, types, record times and non-float fields exactly, float
    fields by more than ``atol``."""
    a, b = BagReader(shipped).arrays(), BagReader(fresh).arrays()
    if set(a) != set(b):
        return [f"topics {sorted(a)} vs {sorted(b)}"]
    found = []
    for topic in sorted(a):
        x, y = a[topic], b[topic]
        same_times = np.array_equal(x.log_time, y.log_time)
        if x.msgtype != y.msgtype or set(x.fields) != set(y.fields) or not same_times:
            found.append(f"{topic}: type, fields or record times differ")
            continue
        for path, column in x.fields.items():
            other = y.fields[path]
            if column.shape != other.shape:
                found.append(f"{topic} {path}: shape {column.shape} vs {other.shape}")
            elif column.dtype.kind == "f":
                both_nan = np.isnan(column) & np.isnan(other)
                worst = float(np.max(np.where(both_nan, 0.0, np.abs(column - other)), initial=0.0))
                if not worst <= atol:
                    found.append(f"{topic} {path}: differs by {worst:.3g}")
            elif not np.array_equal(column, other):
                found.append(f"{topic} {path}: differs")
    return found
