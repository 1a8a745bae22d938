"""Avoidance zones in a velocity IK, for any machine: the monitored points' positions and velocities
at the full command in, the one factor the whole command is scaled by and what to say about it out
(numpy, no ROS; docs/zones.md). The node supplies its machine's points (names, positions and
velocities in the base frame: :meth:`manipulator_kinematics.hydraulic.HydraulicModel.monitored`
for the hydraulic family, :class:`excavator_kinematics.core.monitored.MonitoredPoints` for the
excavator) and the actuator rates of the command; :mod:`manipulator_kinematics.nodes.zone_output`
adds the topic.

The factor is :meth:`manipulator_kinematics.zones.Monitor.check`'s, for the command the node's own
rules (stroke ends, speed limits) already gave: applied to it, the command's overall factor is the
smaller of the two rules' (the zone rule at a command already slowed to k x the target needs
k s' = s of the full target, the same quadratic), and its direction is kept. Below
:data:`STOP_SCALE` the command is stopped outright: the last fractions of a millimetre before the
boundary are not worth a creeping machine, and "stopped" is then what it does.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from manipulator_kinematics.param_files import ConfigError
from manipulator_kinematics.zones import Check, Monitor, Surface, Zone, load_zones, stop_time

#: A zone factor below this stops the command (module docstring).
STOP_SCALE = 0.01
#: Recent command gaps :class:`CommandTimes` looks at, and the longest gap that still counts (s).
GAPS, MAX_GAP = 50, 0.5
#: A state older than this (s, the node's clock minus its stamp: another machine's clock) is
#: taken as this old: a clock skew must not stop the machine.
MAX_AGE = 0.5
#: States of a command as the zones see it.
CLEAR, SLOWED, STOPPED = "clear", "slowed", "stopped"


@dataclass(frozen=True)
class Verdict:
    """One command checked against the zones: ``scale`` to apply to it, ``state`` (CLEAR, SLOWED
    or STOPPED), ``message`` for the status and the log ("" when clear) and the full check."""

    scale: float
    state: str
    message: str
    check: Check


class ZoneGuard:
    """The zones of one node and its monitored points, checked per command.

    ``decelerations`` (m,) are the actuators' deceleration limits (rad/s^2 or m/s^2) in the order
    of the rates the node commands; ``period`` (s) is the longest a command acts before the next
    one can slow it (the control period plus the loop's latency); ``lag`` (s) the actuators'
    first-order time constant (0: they follow a command at once), for which a command goes on
    acting after the next one arrives. The guard remembers its last verdict: that command is
    still in force while the next one is on its way (:meth:`check`'s ``delay``).
    """

    def __init__(
        self,
        zones: Sequence[Zone],
        points: Sequence[str],
        decelerations: Sequence[float],
        period: float,
        lag: float = 0.0,
    ) -> None:
        self.monitor = Monitor(zones, points)
        self.decelerations = np.asarray(decelerations, dtype=float)
        self.period, self.lag = float(period), float(lag)
        # The approach speeds (P, K) of the command in force: the last verdict's scale x its check's.
        self.in_flight: np.ndarray | None = None

    @property
    def zones(self) -> list[Zone]:
        return self.monitor.zones

    @classmethod
    def from_file(
        cls,
        path: str | Path,
        points: Sequence[str],
        decelerations: Sequence[float],
        period: float,
        read_surface: Callable[[str, str], Surface] | None = None,
        setting: str = "zones_file",
        site_pose: bool = False,
        lag: float = 0.0,
    ) -> ZoneGuard:
        """The zones of a zone file; ConfigError ``"<setting>: <path>: zones.<name>.<key>: ..."``
        (one line) for a malformed file, and for a site-frame zone where the node has no site
        pose (``site_pose`` false): without one it could not move toward it at all."""
        try:
            zones = load_zones(path, read_surface)
            for zone in zones:
                if zone.frame == "site" and not site_pose:
                    raise ConfigError(
                        f"zones.{zone.name}.frame: site, but this node has no site pose: give the "
                        "zone in the base frame"
                    )
        except ConfigError as error:
            raise ConfigError(f"{setting}: {path}: {' '.join(str(error).split())}") from None
        return cls(zones, points, decelerations, period, lag)

    def check(
        self,
        positions: np.ndarray,
        velocities: np.ndarray,
        rates: np.ndarray,
        site: tuple[np.ndarray, np.ndarray] | None = None,
        period: float | None = None,
        accelerations: np.ndarray | None = None,
        delay: float = 0.0,
    ) -> Verdict:
        """The verdict on the command ``rates`` (the node's actuator rates) that moves the points at
        ``positions`` (P, 3) with ``velocities`` (P, 3) and ``accelerations`` (P, 3: along the
        command's path at constant rates; None: taken as straight) (base frame); ``period``: the
        time this command may act, when the node knows it is longer than the set one (else that);
        ``delay``: how long from the state's sample the command in force (this guard's last
        verdict) goes on before this one takes over (the state's way in and the command's way
        out), to which the actuators' ``lag`` is added."""
        period = self.period if period is None else max(period, self.period)
        check = self.monitor.check(
            positions,
            velocities,
            stop_time(rates, self.decelerations),
            period,
            site,
            accelerations=accelerations,
            in_flight=self.in_flight,
            delay=delay + self.lag,
        )
        scale = check.scale if check.scale >= STOP_SCALE else 0.0
        self.in_flight = scale * check.approach
        return Verdict(scale, *describe(check, scale), check)

    def watch(self, positions: np.ndarray, site: tuple[np.ndarray, np.ndarray] | None = None) -> Check:
        """The clearances of points standing still (no command: none in force after it)."""
        p = np.asarray(positions, dtype=float)
        self.in_flight = None
        return self.monitor.check(p, np.zeros_like(p), 0.0, self.period, site)


class CommandTimes:
    """How long a node's command acts, from what its loop shows (docs/zones.md, "In the velocity
    IK"): the command in force goes on for the longest of the last :data:`GAPS` states' ages,
    twice (the state's way in, the new command's way out, which the node cannot see: taken as
    long as the way in at its longest: ``delay``), and the new one acts for that plus the longest
    of the node's last :data:`GAPS` gaps between commands (``period``; a gap over
    :data:`MAX_GAP` is a pause, the machine was stopped, and does not count). On a loaded
    machine, whose commands come late, the approach is slower, not deeper."""

    def __init__(self) -> None:
        self.last: float | None = None
        self.gaps: deque[float] = deque(maxlen=GAPS)
        self.ages: deque[float] = deque(maxlen=GAPS)

    def __call__(self, now: float, sampled: float) -> tuple[float, float]:
        """(period, delay) (s) of a command computed at ``now`` (s) from the state sampled at
        ``sampled`` (s, the same clock)."""
        if self.last is not None and now - self.last <= MAX_GAP:
            self.gaps.append(now - self.last)
        self.last = now
        self.ages.append(min(max(now - sampled, 0.0), MAX_AGE))
        delay = 2.0 * max(self.ages)
        return delay + max(self.gaps, default=0.0), delay


def first_entry(
    zones: Sequence[Zone],
    names: Sequence[str],
    positions: np.ndarray,
    site: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[int, str, str] | None:
    """(sample, zone, point) of the first of the samples ``positions`` (M, P, 3) (a planned path's
    monitored points, base frame) at which a point is inside a zone (clearance < 0), None if
    none is: where a path must end before a zone. Site-frame zones need ``site`` = (R, t),
    p_site = R p + t (ValueError without it)."""
    positions = np.asarray(positions, dtype=float)
    first: tuple[int, str, str] | None = None
    for zone in zones:
        if zone.frame == "site":
            if site is None:
                raise ValueError(f"zone {zone.name} is in the site frame: no site pose given")
            c = zone.clearance(positions @ np.asarray(site[0], float).T + site[1])[0]
        else:
            c = zone.clearance(positions)[0]  # (M, P)
        inside = np.flatnonzero(np.any(c < 0.0, axis=1))
        if len(inside) and (first is None or inside[0] < first[0]):
            k = int(inside[0])
            first = (k, zone.name, names[int(np.argmin(c[k]))])
    return first


def describe(check: Check, scale: float) -> tuple[str, str]:
    """(state, sentence) of a command the zones scaled by ``scale``, naming zone and point: e.g.
    ("stopped", "stopped: bucket_tip at zone power_line"). The sentence has no numbers, so a stop
    is said once (a node says it on a change)."""
    if scale >= 1.0 or check.zone is None:
        return CLEAR, ""
    zone, point = check.zone, check.point or "a monitored point"
    if check.clearance[zone][0] < 0.0:
        inside = check.clearance[zone][1]
        return STOPPED, (
            f"{STOPPED}: {inside} inside zone {zone} (zones.{zone}): only motion out of it is allowed"
        )
    if scale == 0.0:
        return STOPPED, f"{STOPPED}: {point} at zone {zone}"
    return SLOWED, f"{SLOWED}: {point} approaching zone {zone}"


__all__ = [
    "CLEAR",
    "SLOWED",
    "STOPPED",
    "STOP_SCALE",
    "CommandTimes",
    "Verdict",
    "ZoneGuard",
    "describe",
    "first_entry",
]
