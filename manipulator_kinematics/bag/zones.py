"""The avoidance zones of a recorded run: each zone's smallest clearance and its transgressions,
from the ``zone_clearance`` topic (diagnostic_msgs/DiagnosticArray, one status per zone: name =
zone, values ``clearance`` and ``point``; :mod:`manipulator_kinematics.nodes.zone_output`).

A transgression is a run of consecutive messages in which the zone's smallest clearance is below
0 (a monitored point inside the zone grown by its margin): its start and end (s since the report's
time origin, header stamps), its deepest clearance and the point that had it. Any machine's
``analyse`` hook adds :func:`zone_report` under ``zones`` when the topic was recorded;
``mk_evaluate`` prints it as a table and lists every transgression.
"""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np

from manipulator_kinematics.bag.analysis import since
from manipulator_kinematics.bag.reader import TopicArrays

#: Transgressions listed per zone at most (all are counted).
LISTED = 20


def _statuses(topic: TopicArrays) -> int:
    count = 0
    while f"status[{count}].name" in topic.fields:
        count += 1
    return count


def _value(topic: TopicArrays, status: int, key: str) -> np.ndarray:
    """The string value of ``key`` in status ``status`` of every message ('' where absent)."""
    out = np.full(len(topic), "", dtype=object)
    j = 0
    while f"status[{status}].values[{j}].key" in topic.fields:
        hit = topic[f"status[{status}].values[{j}].key"] == key
        out[hit] = topic[f"status[{status}].values[{j}].value"][hit]
        j += 1
    return out


def _floats(text: np.ndarray) -> np.ndarray:
    out = np.full(len(text), np.nan)
    for i, t in enumerate(text):
        with contextlib.suppress(ValueError):  # absent or not a number: no clearance in this message
            out[i] = float(t)
    return out


def zone_report(topic: TopicArrays, t0: int) -> dict[str, Any]:
    """Per zone (by name, in the order first seen): messages, the smallest clearance (m), its point
    and time, and the transgressions (module docstring)."""
    t = since(topic.stamp_ns(), t0)
    rows: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}
    for i in range(_statuses(topic)):
        names = topic[f"status[{i}].name"]
        clearance, point = _floats(_value(topic, i, "clearance")), _value(topic, i, "point")
        for name in dict.fromkeys(n for n in names.tolist() if n):
            hit = (names == name) & np.isfinite(clearance)
            rows.setdefault(name, []).append((t[hit], clearance[hit], point[hit]))
    report: dict[str, Any] = {}
    for name, parts in rows.items():
        order = np.argsort(np.concatenate([p[0] for p in parts]), kind="stable")
        times, c, points = (np.concatenate([p[k] for p in parts])[order] for k in range(3))
        if not len(c):
            report[name] = {"messages": 0}
            continue
        k = int(np.argmin(c))
        inside = c < 0.0
        edges = np.flatnonzero(np.diff(np.r_[0, inside.astype(int), 0]))
        runs = list(zip(edges[::2], edges[1::2], strict=True))
        listed = []
        for start, end in runs[:LISTED]:
            deepest = start + int(np.argmin(c[start:end]))
            listed.append(
                {
                    "start_s": float(times[start]),
                    "end_s": float(times[end - 1]),
                    "deepest_m": float(c[deepest]),
                    "point": str(points[deepest]),
                }
            )
        report[name] = {
            "messages": len(c),
            "min_clearance_m": float(c[k]),
            "point": str(points[k]),
            "at_s": float(times[k]),
            "transgressions": len(runs),
            "messages_inside": int(inside.sum()),
            "listed": listed,
        }
    return report


__all__ = ["zone_report"]
