"""mk_evaluate: check a bag of the package's topics against the kinematics; table, JSON and plots.

    mk_evaluate BAG [-o DIR] [--params FILE ...] [--no-plots] [--recover]

Finds the registered machines (:mod:`manipulator_kinematics.registry`) in each namespace of the
bag, by their joint names and topics (:func:`machines_in`), has each one's ``analyse`` hook
recompute its kinematics from the recorded inputs with its numpy core and report the error of
the published outputs (and what else the machine checks: the excavator's command tracking,
cylinder speeds and strokes), and reports per topic the message rate, gaps and latency (see
:mod:`manipulator_kinematics.bag.analysis`). Models come from ``--params`` files (each machine
whose parameter section they hold, validated) or are the machines' shipped defaults. Writes
``report.json`` and PNG plots to DIR (default: ``<bag>_evaluation`` beside the bag); nothing is
written when the bag cannot be read.
Needs no ROS installation beyond the message definitions that rosbags ships.
"""

from __future__ import annotations

import argparse
import difflib
import json
import math
import sys
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from manipulator_kinematics.bag import analysis
from manipulator_kinematics.bag.analysis import AnalysisContext, Panel, Plot
from manipulator_kinematics.bag.cli import guarded
from manipulator_kinematics.bag.reader import BagReader, BagStream, TopicArrays
from manipulator_kinematics.bag.topics import (
    JOINT_STATE,
    SETTINGS_KEY,
    decode_recorded_settings,
    node_sections,
    node_settings,
    package_topics,
)
from manipulator_kinematics.bag.types import BagError
from manipulator_kinematics.param_files import flatten, load_parameters, merge, unflatten
from manipulator_kinematics.registry import Machine, machines, machines_described

NAME = "mk_evaluate"
# Points per curve in a plot: each bin keeps its min and max, so spikes stay visible.
PLOT_BINS = 2000
ASSUMED = "not in the bag, assumed the package's defaults"


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog=NAME, description=__doc__.split("\n\n")[0])
    parser.add_argument("bag", type=Path)
    parser.add_argument(
        "-o", "--output", type=Path, help="directory for report.json and plots (default: <bag>_evaluation)"
    )
    parser.add_argument(
        "--params",
        nargs="+",
        type=Path,
        default=[],
        metavar="FILE",
        help="ROS parameter files with machines (a registered machine's section under /**, "
        "complete) and node settings (/**/<node> sections); default: the shipped machines and settings",
    )
    parser.add_argument("--no-plots", action="store_true", help="write no PNG files")
    parser.add_argument(
        "--recover",
        action="store_true",
        help="read an mcap bag whose recorder was killed, up to its last flush",
    )
    return parser.parse_args(argv)


def split_topic(topic: str, names: Sequence[str]) -> tuple[str, str] | None:
    """(namespace, package topic name) of a recorded topic, or None when it is not one of ours."""
    for name in sorted(names, key=len, reverse=True):
        if topic == "/" + name or topic.endswith("/" + name):
            return topic[: -len(name) - 1] or "/", name
    return None


@dataclass
class Setup:
    """What evaluate recomputes with: models by machine name (the default model of a machine not
    given is built when first needed), node name -> settings (:class:`AnalysisContext`: the
    package's, with ``given`` over them) and ``given``: the node settings of ``--params`` files,
    which also win over the settings recorded in a bag."""

    models: dict[str, Any] = field(default_factory=dict)
    node_settings: Mapping[str, Mapping[str, Any]] = field(default_factory=node_settings)
    given: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def model(self, machine: Machine) -> Any:
        if machine.name not in self.models:
            self.models[machine.name] = machine.model()
        return self.models[machine.name]

    def settings_in(
        self, namespace: str, recorded: Mapping[str, Mapping[str, Any]]
    ) -> tuple[dict[str, dict[str, Any]], dict[str, str]]:
        """Node name -> settings for the nodes of ``namespace`` (the package's, then what the bag
        recorded for ``<namespace>/<node>``, then ``--params``), and node name -> where they came from."""
        prefix = namespace.rstrip("/") + "/"
        here = {
            node[len(prefix) :]: values
            for node, values in recorded.items()
            if node.startswith(prefix) and "/" not in node[len(prefix) :]
        }
        settings, sources = {}, {}
        for name in dict.fromkeys([*self.node_settings, *here]):
            layers = (self.node_settings.get(name, {}), here.get(name, {}), self.given.get(name, {}))
            settings[name] = merge(*layers)
            origin = "recorded in the bag" if name in here else ASSUMED
            sources[name] = origin + ", --params" * (name in self.given)
        return settings, sources


class _Consulted(Mapping[str, Any]):
    """Node settings that remember which nodes' settings an analysis looked at."""

    def __init__(self, settings: Mapping[str, Any]) -> None:
        self.settings, self.seen = settings, set()

    def __getitem__(self, node: str) -> Any:
        self.seen.add(node)
        return self.settings[node]

    def __iter__(self) -> Iterator[str]:
        return iter(self.settings)

    def __len__(self) -> int:
        return len(self.settings)


def load_setup(files: Sequence[Path]) -> Setup:
    """Models and node settings from ROS parameter files: under ``/**`` the section of each
    registered machine (validated: the merged section must be complete), node sections
    (``excavator_forward``, ``/**/excavator_forward``, ...) over the package's node settings; a
    later file's value wins key by key, as it does for a node given several files."""
    params: dict[str, Any] = {}
    nodes: dict[str, dict[str, Any]] = {}
    try:
        for path in files:
            if not path.is_file():
                raise BagError(f"--params {path}: no such file")
            params.update(flatten(load_parameters(path)))
            for node, settings in node_sections(path).items():
                nodes[node] = merge(nodes.get(node, {}), settings)
        models = {}
        top = unflatten(params)
        found = machines_described(top)
        taken = {key for m in found.values() for key in m.also}
        for key, section in top.items():
            machine = found.get(key)
            if machine is not None:
                models[machine.name] = machine.model_of(top)
            elif isinstance(section, dict) and key not in taken:
                known = [m.section for m in machines().values()]
                close = difflib.get_close_matches(key, known, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise BagError(
                    f"--params: {key!r} is not the section of a registered machine{hint}; "
                    f"known: {', '.join(known)}"
                )
        defaults = node_settings()
        settings = {name: merge(defaults.get(name, {}), nodes.get(name, {})) for name in defaults | nodes}
        return Setup(models, settings, nodes)
    except (ValueError, yaml.YAMLError) as error:  # ConfigError (a key named) or a model's refusal
        raise BagError(f"--params: {error}") from None


def machines_in(data: Mapping[str, TopicArrays], setup: Setup) -> list[Machine]:
    """The registered machines (with an ``analyse`` hook) whose nodes ran in one namespace
    (``data``: relative topic name -> arrays): a machine is there when a topic that no other
    machine declares has messages, or when its JointState topics name all its joints."""
    registered = machines()
    declared: dict[str, int] = {}
    for machine in registered.values():
        for topic in machine.topics:
            declared[topic] = declared.get(topic, 0) + 1
    found = []
    for machine in registered.values():
        own = [topic for topic in machine.topics if topic in data]
        if machine.analyse is None or not own:
            continue
        if any(declared[topic] == 1 for topic in own):
            found.append(machine)
            continue
        states = [data[topic] for topic in own if machine.topics[topic] == JOINT_STATE]
        labels = {str(name) for arrays in states for name in np.unique(arrays["name"])}
        names = machine.joint_names(setup.model(machine)) if states else ()
        # The label check first: it spares building the model of every machine that is not there.
        if states and set(names) <= labels:
            seen = np.zeros(len(names), dtype=bool)
            for arrays in states:
                seen |= np.isfinite(arrays.by_name("position", names)).any(axis=0)
            if seen.all():
                found.append(machine)
    return found


def group_topics(bag: BagReader | BagStream) -> dict[str, dict[str, str]]:
    """The package's topics with messages in ``bag``: namespace -> package topic name -> recorded
    topic; BagError when a topic has another type than the package's or none has messages."""
    ours = package_topics()
    grouped: dict[str, dict[str, str]] = {}
    for topic, info in bag.topics.items():
        split = split_topic(topic, list(ours))
        if split is None or not info.count:
            continue
        if info.msgtype != ours[split[1]]:
            raise BagError(
                f"{bag.path}: topic {topic} has type {info.msgtype}, but the package's "
                f"{split[1]} is {ours[split[1]]}"
            )
        grouped.setdefault(split[0], {})[split[1]] = topic
    if not grouped:
        raise BagError(
            f"{bag.path}: none of the package's topics ({', '.join(sorted(ours))}) has messages "
            f"in the bag (it has {', '.join(bag.topics) or 'no topics'})"
        )
    return grouped


def recorded_settings(bag: BagReader | BagStream) -> dict[str, dict[str, Any]]:
    """Full node name -> settings that ``mk_record`` stored in the bag's metadata (none: {})."""
    try:
        text = bag.custom_data.get(SETTINGS_KEY)
        return {} if text is None else decode_recorded_settings(text)
    except ValueError as error:
        raise BagError(f"{bag.path}: metadata.yaml: {error}") from None


def evaluate_bag(bag: BagReader, setup: Setup | None = None) -> tuple[dict[str, Any], list[Plot]]:
    """The whole report (JSON-ready) and its plots; ``setup`` default: the shipped machines."""
    setup = Setup() if setup is None else setup
    if bag.message_count == 0:
        raise BagError(f"{bag.path}: the bag holds no messages")
    grouped = group_topics(bag)
    arrays = bag.arrays([topic for names in grouped.values() for topic in names.values()])
    t0 = min(int(bag.log_times(t)[0]) for t, info in bag.topics.items() if info.count)
    end = max(int(bag.log_times(t)[-1]) for t, info in bag.topics.items() if info.count)

    report: dict[str, Any] = {
        "bag": str(bag.path),
        "storage": bag.storage,
        "messages": bag.message_count,
        "duration_s": (end - t0) * 1e-9,
        "recovered": bag.recovered,
        "topics": {},
        "machines": [],
    }
    for topic, info in bag.topics.items():
        if topic in arrays:
            report["topics"][topic] = analysis.topic_stats(arrays[topic])
        else:
            report["topics"][topic] = {"type": info.msgtype, "count": info.count, "evaluated": False}
    plots: list[Plot] = [_latency_plot(arrays, t0)] if arrays else []
    stamp0 = min(
        (int(a.stamp_ns().min()) for a in arrays.values() if len(a) and "header.stamp.sec" in a.fields),
        default=t0,
    )
    recorded = recorded_settings(bag)
    report["recorded_node_settings"] = sorted(recorded)
    for namespace, names in sorted(grouped.items()):
        data: dict[str, TopicArrays] = {name: arrays[topic] for name, topic in names.items()}
        prefix = "" if namespace == "/" else namespace.strip("/").replace("/", "_") + "_"
        settings, sources = setup.settings_in(namespace, recorded)
        for machine in machines_in(data, setup):
            consulted = _Consulted(settings)
            context = AnalysisContext(stamp0, f"{prefix}{machine.name}_", consulted)
            own = {topic: data[topic] for topic in machine.topics if topic in data}
            section, figures = machine.analyse(own, setup.model(machine), context)
            used = {node: sources[node] for node in sorted(consulted.seen)}
            report["machines"].append(
                {"kind": machine.name, "namespace": namespace, "settings_sources": used, **section}
            )
            plots += figures
    return report, plots


def _latency_plot(arrays: dict[str, TopicArrays], t0: int) -> Plot:
    curves = {
        topic: (analysis.since(a.log_time, t0), (a.log_time - a.stamp_ns()) * 1e-9)
        for topic, a in arrays.items()
        if len(a) and "header.stamp.sec" in a.fields
    }
    return Plot("latency", "Latency: record time - header stamp", [Panel("latency (s)", curves)])


# ------------------------------------------------------------------------------------------ output


def _number(value: Any, digits: int = 4) -> str:
    if value is None:
        return "-"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, float) and (value == 0 or 1e-3 <= abs(value) < 1e5):
        return f"{value:.{digits}g}"
    return f"{value:.{digits - 1}e}"


def _table(header: Sequence[str], rows: list[Sequence[Any]]) -> str:
    cells = [list(header)] + [[c if isinstance(c, str) else _number(c) for c in row] for row in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(header))]
    lines = [
        "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths)))
        for row in cells
    ]
    return "\n".join([lines[0], "  ".join("-" * w for w in widths), *lines[1:]])


def render(report: dict[str, Any]) -> str:
    """The report as text tables."""
    out = [
        f"bag {report['bag']} ({report['storage']}): {report['messages']} messages over "
        f"{report['duration_s']:.3f} s"
    ]
    if report["recovered"]:
        out.append(f"RECOVERED: {report['recovered']}")
    rows = []
    for topic, t in report["topics"].items():
        latency = t.get("latency_s") or {}
        rows.append(
            [
                topic,
                t["count"],
                t.get("rate_hz"),
                t.get("gap_max_s"),
                t.get("gaps"),
                latency.get("median"),
                latency.get("p99"),
                latency.get("max"),
            ]
        )
    out += [
        "",
        "Topics",
        _table(["topic", "count", "rate Hz", "max gap s", "gaps", "latency s median", "p99", "max"], rows),
    ]
    for machine in report["machines"]:
        out += ["", f"{machine['kind']} in namespace {machine['namespace']}"]
        by_source: dict[str, list[str]] = {}
        for node, source in machine["settings_sources"].items():
            by_source.setdefault(source, []).append(node)
        out += [f"node settings of {', '.join(nodes)}: {source}" for source, nodes in by_source.items()]
        if used := machine.get("settings_used"):
            out.append("  used: " + ", ".join(f"{key} {_setting(value)}" for key, value in used.items()))
        errors = []
        for topic, entry in machine.get("consistency", {}).items():
            for quantity, stats in entry.items():
                if isinstance(stats, dict):
                    errors.append(
                        [
                            f"{topic} {quantity}",
                            entry["matched"],
                            entry["unmatched"],
                            stats["max"],
                            stats["rms"],
                        ]
                    )
        if errors:
            out += [
                "consistency with the recomputed kinematics",
                _table(["output", "matched", "unmatched", "max error", "RMS error"], errors),
            ]
            out += [
                f"  {topic}: {entry['not_compared']}"
                for topic, entry in machine.get("consistency", {}).items()
                if "not_compared" in entry
            ]
        pairs = [
            [
                f"cylinder_lengths -> {topic}",
                c["recorded"],
                c["accepted"],
                c["due"],
                c["answered"],
                c["missing"],
                c["outside_recording"],
            ]
            for topic, c in machine.get("inputs_to_outputs", {}).items()
        ]
        if pairs:
            out += [
                "inputs and outputs (due: accepted and not skipped by a rate limit; missing: due, "
                "no output, within the recording of the output)",
                _table(
                    [
                        "input -> output",
                        "recorded",
                        "accepted",
                        "due",
                        "answered",
                        "missing",
                        "outside recording",
                    ],
                    pairs,
                ),
            ]
            out += [
                f"  SHORTFALL: {row[5]} of {row[3]} due inputs have no {row[0].split(' -> ')[1]}, more "
                "than the node's settings explain"
                for row in pairs
                if row[5]
            ]
        if zones := machine.get("zones"):
            out += [
                "avoidance zones: zone_clearance (clearance: distance from the zone grown by its margin)",
                _table(
                    ["zone", "messages", "min clearance m", "point", "at s", "transgressions"],
                    [
                        [
                            name,
                            z["messages"],
                            z.get("min_clearance_m"),
                            z.get("point", "-"),
                            z.get("at_s"),
                            z.get("transgressions", 0),
                        ]
                        for name, z in zones.items()
                    ],
                ),
            ]
            out += [
                f"  TRANSGRESSION {name}: {e['point']} {-e['deepest_m']:.4g} m inside, "
                f"{e['start_s']:.3f} to {e['end_s']:.3f} s"
                for name, z in zones.items()
                for e in z.get("listed", [])
            ]
        if "tracking" in machine:
            tr = machine["tracking"]
            out += [
                "tracking: target_bucket_twist vs bucket_twist",
                _table(
                    ["quantity", "matched", "no command", "max error", "RMS error"],
                    [
                        [q, tr["matched"], tr["without_active_command"], tr[q]["max"], tr[q]["rms"]]
                        for q in ("linear_mps", "angular_radps")
                    ],
                ),
            ]
        actuators = machine.get("actuators", {})
        cylinders = [
            [
                name,
                a["length_min_m"],
                a["length_max_m"],
                a["stroke_used"],
                a["near_end_fraction"],
                a["beyond_end"],
                a["speed_max_mps"],
                a["speed_limit_mps"],
                a["over_speed"],
                a["non_finite_length"],
                a["non_finite_speed"],
            ]
            for name, a in actuators.items()
            if "length_min_m" in a
        ]
        if cylinders:
            out += [
                "cylinders",
                _table(
                    [
                        "cylinder",
                        "min m",
                        "max m",
                        "stroke used",
                        "near end",
                        "beyond end",
                        "max speed m/s",
                        "limit",
                        "over speed",
                        "NaN/inf length",
                        "NaN/inf speed",
                    ],
                    cylinders,
                ),
            ]
        non_finite = [
            f"{name} {key.removeprefix('non_finite_')} {count} of {a['samples']}"
            for name, a in actuators.items()
            for key, count in a.items()
            if key.startswith("non_finite_") and count
        ]
        if non_finite:
            out.append(f"non-finite samples (not in the statistics): {', '.join(non_finite)}")
        if "commands" in actuators:
            out += [
                "rate commands",
                _table(
                    ["actuator", "max |command|", "limit", "saturated"],
                    [
                        [n, c["max"], c["limit"], c["saturated_fraction"]]
                        for n, c in actuators["commands"].items()
                    ],
                ),
            ]
        if "joint_states" in machine:
            out.append(
                f"joint states: {machine['joint_states']}, outside the joint limits: "
                f"{machine['outside_limits']}"
            )
    return "\n".join(out)


def _setting(value: Any) -> str:
    return str(value).lower() if isinstance(value, bool) else _number(value)


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def _decimate(t: np.ndarray, y: np.ndarray, bins: int = PLOT_BINS) -> tuple[np.ndarray, np.ndarray]:
    """At most 2 * bins points: the min and max of each of ``bins`` equal slices."""
    keep = np.isfinite(t) & np.isfinite(y)
    t, y = t[keep], y[keep]
    if len(t) <= 2 * bins:
        return t, y
    edges = np.linspace(0, len(t), bins + 1).astype(int)
    low = np.minimum.reduceat(y, edges[:-1])
    high = np.maximum.reduceat(y, edges[:-1])
    mid = t[(edges[:-1] + edges[1:]) // 2]
    return np.repeat(mid, 2), np.column_stack([low, high]).ravel()


def _decade_ticks(ax: Any) -> None:
    """At most 7 labelled decades on a log |error| axis (0 and every k-th power of ten): one label
    per decade over 13 decades crowded into each other."""
    low, high = ax.get_ylim()
    top = math.ceil(math.log10(max(high, 1e-12)))
    bottom = max(-12, math.floor(math.log10(max(low, 1e-12))))
    step = max(1, math.ceil((top - bottom) / 6))
    ax.set_yticks([0.0, *(10.0**k for k in range(top, bottom - 1, -step))])


def write_plots(plots: Sequence[Plot], directory: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    for plot in plots:
        panels = [panel for panel in plot.panels if panel.curves]
        if not panels:
            continue
        height = 1.2 + 2.2 * len(panels)
        figure, axes = plt.subplots(len(panels), 1, sharex=True, squeeze=False, figsize=(10, height))
        # Fixed margins: tight_layout measures every tick label and costs seconds per figure.
        figure.subplots_adjust(
            left=0.11, right=0.98, top=1 - 0.45 / height, bottom=0.55 / height, hspace=0.15
        )
        for ax, panel in zip(axes[:, 0], panels):
            for label, (t, y) in panel.curves.items():
                y = np.abs(y) if panel.log else y
                ax.plot(*_decimate(np.asarray(t, float), np.asarray(y, float)), label=label, linewidth=0.8)
            for value in panel.limits:
                ax.axhline(value, color="grey", linestyle="--", linewidth=0.7)
            if panel.log:
                ax.set_yscale("symlog", linthresh=1e-12)
                _decade_ticks(ax)
            ax.set_ylabel(panel.ylabel)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize="small", loc="upper right")
        axes[0, 0].set_title(plot.title)
        axes[-1, 0].set_xlabel("time (s)")
        path = directory / f"{plot.name}.png"
        figure.savefig(path, dpi=90)
        plt.close(figure)
        written.append(path)
    return written


def run_evaluate(argv: Sequence[str]) -> int:
    args = parse_args(argv)
    setup = load_setup(args.params)
    bag = BagReader(args.bag, recover=args.recover)
    # A bag's numbers can be anything (a damaged byte makes 1e300): what overflows is reported as
    # inf, not as numpy warnings on stderr.
    with np.errstate(all="ignore"):
        report, plots = evaluate_bag(bag, setup)
    print(render(report))
    output = args.output or args.bag.parent / f"{args.bag.stem}_evaluation"
    try:
        output.mkdir(parents=True, exist_ok=True)
        tmp = output / "report.json.tmp"
        tmp.write_text(json.dumps(_jsonable(report), indent=2), encoding="utf-8")
        tmp.replace(output / "report.json")
        written = [] if args.no_plots else write_plots(plots, output)
    except OSError as error:
        raise BagError(f"cannot write the report to {output}: {error}") from None
    print(
        f"\nreport: {output / 'report.json'}" + (f", {len(written)} plots in {output}" if written else ""),
        file=sys.stderr,
    )
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    return guarded(NAME, run_evaluate, argv)


if __name__ == "__main__":
    raise SystemExit(main())
