"""Scripted bucket paths and a bucket-position tracking law (numpy only).

A :class:`BucketPath` is a chain of segments in the machine's natural coordinates
C = [r, theta1, z, alpha] (radius from the swing axis, swing angle, height, bucket angle), each
timed by a quintic with zero end velocities and accelerations (:func:`quintic`), so a segment
that changes only theta1 is a swing on a circle and one that changes only r is a drag at constant
depth. :meth:`BucketPath.at` gives the reference Q = [x, y, z, alpha] (eq. 3's task coordinates)
and its rate; :func:`follow` turns reference and measurement into the rate to command.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from manipulator_kinematics.trajectory import quintic


@dataclass(frozen=True)
class Segment:
    name: str
    end: np.ndarray  # C = [r, theta1, z, alpha] at the end of the segment
    duration: float  # s


class BucketPath:
    """Segments from ``start`` (C = [r, theta1, z, alpha]), each ending at rest."""

    def __init__(self, start: np.ndarray, segments: list[Segment]) -> None:
        self.start = np.asarray(start, dtype=float)
        self.segments = segments
        self.starts = np.cumsum([0.0] + [s.duration for s in segments])  # segment start times
        self.duration = float(self.starts[-1])

    def phase(self, t: float) -> int:
        """Index of the segment running at time ``t`` (clamped to the path)."""
        return int(np.clip(np.searchsorted(self.starts, t, side="right") - 1, 0, len(self.segments) - 1))

    def natural(self, t: float, lead: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """C = [r, theta1, z, alpha] at time ``t`` and its rate at ``t + lead`` (a feed-forward
        ahead of a delay); held at the ends."""
        return self._sample(t)[0], self._sample(t + lead)[1]

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Reference Q = [x, y, z, alpha] and Q_dot at time ``t``."""
        return to_task(*self._sample(t))

    def _sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        i = self.phase(t)
        c0 = self.start if i == 0 else self.segments[i - 1].end
        segment = self.segments[i]
        local = float(np.clip(t - self.starts[i], 0.0, segment.duration))
        sample = quintic(c0, segment.end, [local], duration=segment.duration)
        return sample.q[0], sample.qd[0]


def to_task(c: np.ndarray, c_dot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """C = [r, theta1, z, alpha] and its rate -> Q = [x, y, z, alpha] and Q_dot."""
    r, theta1, z, alpha = c
    r_dot, theta1_dot, z_dot, alpha_dot = c_dot
    cos, sin = np.cos(theta1), np.sin(theta1)
    q = np.array([r * cos, r * sin, z, alpha])
    q_dot = np.array(
        [r_dot * cos - r * sin * theta1_dot, r_dot * sin + r * cos * theta1_dot, z_dot, alpha_dot]
    )
    return q, q_dot


def natural_coordinates(theta1: float, q: np.ndarray) -> np.ndarray:
    """C = [r, theta1, z, alpha] of Q = [x, y, z, alpha] at swing angle ``theta1`` (r signed)."""
    return np.array([q[0] * np.cos(theta1) + q[1] * np.sin(theta1), theta1, q[2], q[3]])


def follow(
    reference: np.ndarray,
    reference_rate: np.ndarray,
    measured: np.ndarray,
    gain: float,
    angles: tuple[int, ...] = (3,),
) -> np.ndarray:
    """Rate to command: feed-forward plus ``gain`` (1/s) times the error reference - measured.

    Works in any coordinates; the errors of the ``angles`` entries are wrapped to (-pi, pi]
    (alpha from a quaternion is only known modulo 2 pi). In C = [r, theta1, z, alpha]
    (``angles=(1, 3)``) a bucket that fell behind on a swing catches up along the arc instead of
    cutting the chord.
    """
    error = np.asarray(reference, dtype=float) - np.asarray(measured, dtype=float)
    for i in angles:
        error[i] = (error[i] + np.pi) % (2.0 * np.pi) - np.pi
    return np.asarray(reference_rate, dtype=float) + gain * error


def path_deviation(
    points: np.ndarray, t: np.ndarray, path: np.ndarray, t_path: np.ndarray, window: float = 1.0
) -> np.ndarray:
    """Distance of each of ``points`` (N, 3) at times ``t`` from the polyline ``path`` (M, 3) at
    times ``t_path``, searched within +-``window`` s: how far the bucket left the path, whatever
    its timing along it."""
    out = np.empty(len(points))
    for k, (p, tk) in enumerate(zip(points, t)):
        lo, hi = np.searchsorted(t_path, [tk - window, tk + window])
        a, b = path[max(lo - 1, 0) : hi], path[max(lo - 1, 0) + 1 : hi + 1]
        n = min(len(a), len(b))
        a, b = a[:n], b[:n]
        if n == 0:
            out[k] = np.linalg.norm(path[min(lo, len(path) - 1)] - p)
            continue
        ab = b - a
        u = np.clip(np.sum((p - a) * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-300), 0.0, 1.0)
        out[k] = np.min(np.linalg.norm(a + u[:, None] * ab - p, axis=1))
    return out


def digging_cycle(start: np.ndarray) -> BucketPath:
    """One digging cycle of the CET200 from ``start`` (C of the machine's current state).

    Penetrate ahead of the machine, drag toward it at constant depth, curl, lift, swing 80 deg to
    dump, open the bucket, swing back and return to the start. All of it lies inside the stroke
    box.
    """
    deg = np.pi / 180.0
    dump_swing = 80.0 * deg

    def c(r: float, theta1: float, z: float, alpha_deg: float) -> np.ndarray:
        return np.array([r, theta1, z, alpha_deg * deg])

    # Durations keep every actuator at or below about 85 % of its maximum speed on the reference,
    # leaving room for the feedback of the tracking law.
    back = c(float(start[0]), float(start[1]), float(start[2]), float(start[3]) / deg)
    return BucketPath(
        start,
        [
            Segment("approach", c(7.0, 0.0, 0.6, -95.0), 7.0),
            Segment("penetrate", c(6.8, 0.0, -0.5, -105.0), 2.5),
            Segment("drag", c(4.8, 0.0, -0.5, -130.0), 4.5),
            Segment("curl", c(4.6, 0.0, -0.2, -200.0), 4.5),
            Segment("lift", c(5.0, 0.0, 2.6, -165.0), 8.0),
            Segment("swing", c(5.0, dump_swing, 2.6, -165.0), 3.5),
            Segment("dump", c(5.6, dump_swing, 2.8, -80.0), 6.0),
            Segment("return", back, 4.5),
        ],
    )


class CycleClock:
    """Time along a path from measurement stamps, held while the loop is broken.

    The time advances by the stamp difference between consecutive measurements that were acted
    on, but by at most ``max_step`` s: after a gap longer than the command timeouts the machine
    stood still, so a reference that ran on through the gap would leave the bucket behind
    (and cutting corners to catch up). The held time is counted in :attr:`held`.
    """

    def __init__(self, max_step: float) -> None:
        self.max_step = float(max_step)
        self.start_ns: int | None = None
        self.last_ns: int | None = None
        self.t = 0.0  # s along the path
        self.held = 0.0  # s of stamp time that did not advance the path

    def tick(self, stamp_ns: int) -> float:
        """Advance to a measurement stamped ``stamp_ns`` (ns) and return the time along the path;
        the first call is time 0. A stamp older than the previous one does not move the clock."""
        if self.start_ns is None:
            self.start_ns = self.last_ns = stamp_ns
            return self.t
        step = max(stamp_ns - self.last_ns, 0) * 1e-9
        self.t += min(step, self.max_step)
        self.held += max(step - self.max_step, 0.0)
        self.last_ns = max(stamp_ns, self.last_ns)
        return self.t
