"""mk_asbuilt: what the machines dug, from recorded bags: per-sample Parquet tables, as-built surfaces.

    mk_asbuilt BAG [BAG ...] -o DIR [--cell M] [--params FILE ...] [--recover] [--chunk-seconds S]
    mk_asbuilt --fleet DIR_OR_GLOB -o DIR [--workers N | --scheduler ADDRESS] [...]

For every machine found in a bag (as ``mk_evaluate`` finds them) whose package has a ``samples``
hook (:mod:`manipulator_kinematics.registry`), writes ``DIR/<bag>/<namespace>_<machine>.parquet``:
one row per input its forward node accepted (stamp, actuators, tool pose, cutting-edge corners in
the base and site frame, grade heights where a design is set, status), units in the schema's
metadata (docs/asbuilt.md). From the cutting edge's sweeps (:mod:`manipulator_kinematics.asbuilt`)
it writes the as-built surface, the lowest elevation the edge reached per cell of the site frame:
``asbuilt.xml`` (LandXML 1.2 TIN), ``asbuilt.csv`` (x, y, z per cell) and ``asbuilt.png`` (the
elevation and, where a design surface is set, the lowest height above it reached: cut/fill).

A bag is read in windows of ``--chunk-seconds`` of record time (default 60 s), the table written a
row group a window and the as-built grid merged window by window, so a bag of any length takes the
memory of one window; the result is the whole bag's (:func:`process_bag`).

``--fleet`` evaluates every bag under a folder (or matching a glob) in parallel with Dask: local
processes by default (``--workers``), a running Dask cluster with ``--scheduler``. It writes the
per-bag outputs, one merged table ``fleet.parquet`` (columns ``bag``, ``namespace`` and
``machine`` added), one merged as-built surface and ``fleet.json``: per bag, per machine, per
day. A bag that cannot be read is reported and skipped.
"""

from __future__ import annotations

import argparse
import datetime
import glob
import json
import sys
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from manipulator_kinematics.asbuilt import AsBuilt, LowestElevation
from manipulator_kinematics.bag.analysis import AnalysisContext
from manipulator_kinematics.bag.cli import guarded
from manipulator_kinematics.bag.evaluate import (
    Setup,
    group_topics,
    load_setup,
    machines_in,
    recorded_settings,
)
from manipulator_kinematics.bag.reader import BagStream
from manipulator_kinematics.bag.types import BagError

NAME = "mk_asbuilt"
EDGE = ("left_site_x", "left_site_y", "left_site_z", "right_site_x", "right_site_y", "right_site_z")
GRADE = ("grade_left", "grade_right")
#: A bag is read in windows of this much record time (s); docs/asbuilt.md has the memory it takes.
CHUNK_SECONDS = 60.0
#: Messages this far (s) around a window are read with it: what a row depends on (process_bag).
CHUNK_MARGIN = 2.0


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog=NAME, description=__doc__.split("\n\n")[0])
    parser.add_argument("bags", nargs="*", type=Path, help="bag folders (rosbag2: metadata.yaml + files)")
    parser.add_argument(
        "--fleet",
        metavar="DIR_OR_GLOB",
        help="every bag under this folder, or matching this glob, in parallel",
    )
    parser.add_argument("-o", "--output", type=Path, required=True, help="output folder")
    parser.add_argument("--cell", type=float, default=0.25, help="as-built cell size, m (default 0.25)")
    parser.add_argument(
        "--params",
        nargs="+",
        type=Path,
        default=[],
        metavar="FILE",
        help="ROS parameter files with machines and node settings (as mk_evaluate)",
    )
    parser.add_argument(
        "--workers", type=int, default=None, help="--fleet: local worker processes (default: one per core)"
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="--fleet: a running Dask scheduler (tcp://host:8786) instead of local processes",
    )
    parser.add_argument("--recover", action="store_true", help="read mcap bags whose recorder was killed")
    parser.add_argument(
        "--chunk-seconds",
        type=float,
        default=CHUNK_SECONDS,
        metavar="S",
        help=f"read each bag in windows of this much record time; 0: whole (default {CHUNK_SECONDS:g})",
    )
    parser.add_argument(
        "--chunk-margin",
        type=float,
        default=CHUNK_MARGIN,
        metavar="S",
        help=f"messages this far around a window are read with it (default {CHUNK_MARGIN:g})",
    )
    args = parser.parse_args(argv)
    if bool(args.bags) == bool(args.fleet):
        parser.error("give bags or --fleet, not both and not neither")
    if not (np.isfinite(args.cell) and 0.01 <= args.cell <= 100.0):
        parser.error(f"--cell must be between 0.01 and 100 m, got {args.cell}")
    if args.workers is not None and not 1 <= args.workers <= 256:
        parser.error(f"--workers must be between 1 and 256, got {args.workers}")
    if not (np.isfinite(args.chunk_seconds) and args.chunk_seconds >= 0.0):
        parser.error(f"--chunk-seconds must be 0 (whole bag) or positive, got {args.chunk_seconds}")
    if not (np.isfinite(args.chunk_margin) and args.chunk_margin >= 0.0):
        parser.error(f"--chunk-margin must be 0 or positive, got {args.chunk_margin}")
    args.chunk_seconds = args.chunk_seconds or None
    return args


@dataclass
class BagResult:
    """What one bag gave: its tables (path, rows, machine, namespace), as-built grids by machine
    key, a summary for the fleet report, or the error that made it unreadable."""

    bag: str
    tables: list[dict[str, Any]] = field(default_factory=list)
    grids: dict[str, AsBuilt] = field(default_factory=dict)
    grade_grids: dict[str, AsBuilt] = field(default_factory=dict)
    error: str | None = None


@cache
def _setup(params: tuple[Path, ...]) -> Setup:
    """Models and node settings of ``params``, once per process (a fleet's workers build their
    own: a model is not sent between processes)."""
    return load_setup(params)


def process_bag(
    path: Path,
    output: Path,
    params: Sequence[Path],
    cell: float,
    recover: bool = False,
    chunk_seconds: float | None = CHUNK_SECONDS,
    chunk_margin: float = CHUNK_MARGIN,
) -> BagResult:
    """One bag's tables and as-built surfaces into ``output/<bag name>``, with the machines and
    node settings of ``params`` (as mk_evaluate --params); a bag that cannot be read gives a
    result with ``error`` set and leaves no table behind.

    The bag is read in windows of ``chunk_seconds`` of record time (None: whole), each with the
    messages ``chunk_margin`` seconds around it (:meth:`BagStream.windows`): the table is written
    window by window (a Parquet row group each) and the as-built grids merged as they come, so
    memory stays that of one window whatever the bag's length. A row depends on messages at most
    ``chunk_margin`` away in record time (the excavator's: its swing state, site pose and previous
    input within their max ages, its output pose recorded after it), so the result is the whole
    bag's. A machine that ``mk_evaluate``'s rule finds only by its joint names counts from the
    first window where they are all there."""
    setup = _setup(tuple(params))
    result = BagResult(str(path))
    folder = output / path.name
    tables: dict[str, _Table] = {}
    try:
        bag = BagStream(path, recover=recover)
        if bag.message_count == 0:
            raise BagError(f"{path}: the bag holds no messages")
        grouped = group_topics(bag)
        recorded = recorded_settings(bag)
        topics = [topic for names in grouped.values() for topic in names.values()]
        # As mk_evaluate: the settings recorded in the bag, --params over them.
        settings_in = {namespace: setup.settings_in(namespace, recorded)[0] for namespace in grouped}
        for part in bag.windows(chunk_seconds, chunk_margin):
            arrays = part.arrays(topics)
            for namespace, names in sorted(grouped.items()):
                data = {name: arrays[topic] for name, topic in names.items()}
                prefix = "" if namespace == "/" else namespace.strip("/").replace("/", "_") + "_"
                settings = settings_in[namespace]
                for machine in machines_in(data, setup):
                    if machine.samples is None:
                        continue
                    key = f"{prefix}{machine.name}"
                    context = AnalysisContext(0, f"{key}_", settings)
                    own = {topic: data[topic] for topic in machine.topics if topic in data}
                    with np.errstate(all="ignore"):  # a damaged record's 1e300 is a value, not a warning
                        columns, units = machine.samples(own, setup.model(machine), context)
                    if key not in tables:
                        tables[key] = _Table(folder / f"{key}.parquet", machine.name, namespace, cell)
                    tables[key].add(columns, units, part.owns(columns["stamp_ns"]), str(path))
    except BagError as error:
        for table in tables.values():
            table.discard()
        result.error = " ".join(str(error).split())
        return result
    for key, table in tables.items():
        table.close()
        result.tables.append(
            {
                "file": str(table.file),
                "machine": table.machine,
                "namespace": table.namespace,
                "rows": table.rows,
                "days": dict(sorted(table.days.items())),
            }
        )
        if table.edge is None or not table.rows:
            continue
        grid = table.edge.result()
        result.grids[key] = grid
        _write_surface(grid, folder / f"{key}_asbuilt", f"{path.name} {key}")
        if table.grade is not None:
            result.grade_grids[key] = table.grade.result()
        _write_map(
            grid, result.grade_grids.get(key), folder / f"{key}_asbuilt.png", f"as-built: {path.name} {key}"
        )
    return result


class _Table:
    """One machine's per-sample table, written a window at a time (a row group each), and its
    as-built runs (cutting edge; edge on the design) fed with the same rows."""

    def __init__(self, file: Path, machine: str, namespace: str, cell: float) -> None:
        self.file, self.machine, self.namespace, self.cell = file, machine, namespace, cell
        self.writer: Any = None
        self.rows = 0
        self.days: Counter[str] = Counter()
        self.edge: LowestElevation | None = None
        self.grade: LowestElevation | None = None

    def add(self, columns: dict[str, np.ndarray], units: dict[str, str], keep: np.ndarray, bag: str) -> None:
        """The rows ``keep`` of a window's ``columns`` (the samples hook's, in stamp order)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        columns = {name: np.asarray(values)[keep] for name, values in columns.items()}
        table = pa.table(columns)
        if self.writer is None:
            metadata = {
                "units": json.dumps(_units(list(columns), units)),
                "machine": self.machine,
                "namespace": self.namespace,
                "bag": bag,
            }
            self.file.parent.mkdir(parents=True, exist_ok=True)
            self.writer = pq.ParquetWriter(self.file, table.schema.with_metadata(metadata))
            if all(c in columns for c in EDGE):
                self.edge = LowestElevation(self.cell)
                if all(c in columns for c in GRADE):
                    self.grade = LowestElevation(self.cell)
        if table.num_rows:  # a window without rows (a gap in the record) adds no row group
            self.writer.write_table(table.cast(self.writer.schema))
        stamps = columns["stamp_ns"]
        self.rows += len(stamps)
        self.days.update(_days(stamps))
        if self.edge is not None:
            left = np.column_stack([columns[c] for c in EDGE[:3]])
            right = np.column_stack([columns[c] for c in EDGE[3:]])
            self.edge.add(left, right)
            if self.grade is not None:
                self.grade.add(
                    np.column_stack([left[:, :2], columns[GRADE[0]]]),
                    np.column_stack([right[:, :2], columns[GRADE[1]]]),
                )

    def close(self) -> None:
        self.writer.close()

    def discard(self) -> None:
        """The bag turned out unreadable: no partial table is left."""
        self.writer.close()
        self.file.unlink(missing_ok=True)


def _units(names: list[str], units: dict[str, str]) -> dict[str, str]:
    """Each column's unit: its own entry, else the longest prefix entry (``grade_``)."""
    out = {}
    for name in names:
        prefixes = [p for p in units if name.startswith(p)]
        out[name] = units.get(name) or (units[max(prefixes, key=len)] if prefixes else "")
    return out


def _days(stamps: np.ndarray) -> dict[str, int]:
    """Rows per UTC day of their stamps."""
    if not len(stamps):
        return {}
    days, counts = np.unique(stamps // 86_400_000_000_000, return_counts=True)
    return {
        str(datetime.date(1970, 1, 1) + datetime.timedelta(days=int(d))): int(c)
        for d, c in zip(days, counts, strict=True)
    }


def _write_surface(grid: AsBuilt, stem: Path, name: str) -> None:
    grid.write_landxml(stem.with_suffix(".xml"), name)
    grid.write_csv(stem.with_suffix(".csv"))


def _write_map(grid: AsBuilt, grade: AsBuilt | None, path: Path, title: str) -> None:
    """Elevation map and, with a design, the lowest height above it reached (cut/fill)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = 1 if grade is None else 2
    figure, axes = plt.subplots(1, panels, figsize=(6.5 * panels, 5.8), squeeze=False)
    extent = (0.0, grid.z.shape[1] * grid.cell, 0.0, grid.z.shape[0] * grid.cell)
    image = axes[0, 0].imshow(grid.z, origin="lower", extent=extent, cmap="terrain")
    figure.colorbar(image, ax=axes[0, 0], label="lowest edge elevation (m)")
    axes[0, 0].set_title("as-built elevation")
    if grade is not None:
        placed = grade.on(grid.x0, grid.y0, grid.z.shape)
        limit = max(float(np.nanmax(np.abs(placed.z))) if np.isfinite(placed.z).any() else 0.0, 0.01)
        image = axes[0, 1].imshow(
            placed.z, origin="lower", extent=extent, cmap="RdBu_r", vmin=-limit, vmax=limit
        )
        figure.colorbar(image, ax=axes[0, 1], label="lowest height above design (m): + to cut, - over-dug")
        axes[0, 1].set_title("cut / fill against the design")
    for ax in axes[0]:
        ax.set_xlabel(f"easting - {grid.x0:.2f} (m)")
        ax.set_ylabel(f"northing - {grid.y0:.2f} (m)")
        ax.set_aspect("equal")
    figure.suptitle(f"{title} (cell {grid.cell:g} m)")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def fleet_bags(pattern: str) -> list[Path]:
    """The bag folders (holding a metadata.yaml) under a folder or matching a glob, sorted."""
    root = Path(pattern)
    if root.is_dir():
        found = {p.parent for p in root.rglob("metadata.yaml")}
    else:
        found = {Path(p) for p in glob.glob(pattern, recursive=True) if Path(p, "metadata.yaml").is_file()}
    if not found:
        raise BagError(f"--fleet {pattern}: no bag (a folder with metadata.yaml) found")
    return sorted(found)


def run_fleet(
    paths: Sequence[Path],
    output: Path,
    params: Sequence[Path],
    cell: float,
    workers: int | None = None,
    scheduler: str | None = None,
    recover: bool = False,
    chunk_seconds: float | None = CHUNK_SECONDS,
    chunk_margin: float = CHUNK_MARGIN,
) -> list[BagResult]:
    """Every bag processed by Dask (local processes, or the cluster at ``scheduler``), with a
    progress bar on stderr; the results in the order of ``paths``."""
    import dask
    from dask import delayed

    tasks = [
        delayed(process_bag)(p, output, tuple(params), cell, recover, chunk_seconds, chunk_margin)
        for p in paths
    ]
    if scheduler:
        from distributed import Client, progress

        with Client(scheduler) as client:
            futures = client.compute(tasks)
            progress(futures)
            return client.gather(futures)
    from dask.diagnostics import ProgressBar

    # One bag a task (chunksize=1): the process scheduler hands out tasks in chunks of 6 by
    # default, so 20 bags on 2 workers ran as chunks of 6, 6, 6 and 2 (1.48x over one worker on
    # an idle 2-core machine); a bag takes seconds, a task's hand-over milliseconds.
    with ProgressBar(dt=1.0, out=sys.stderr):
        return list(dask.compute(*tasks, scheduler="processes", num_workers=workers, chunksize=1))


def merge_tables(results: Sequence[BagResult], path: Path) -> int:
    """One Parquet file of every table, with ``bag``, ``namespace`` and ``machine`` columns;
    written row group by row group (one window of one bag in memory at a time). Returns the rows."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    entries = [(r.bag, t) for r in results for t in r.tables]
    if not entries:
        return 0
    schemas = [pq.read_schema(t["file"]).remove_metadata() for _, t in entries]
    key = pa.schema([("bag", pa.string()), ("namespace", pa.string()), ("machine", pa.string())])
    schema = pa.unify_schemas([key, *schemas])
    rows = 0
    with pq.ParquetWriter(path, schema) as writer:
        for bag, entry in entries:
            source = pq.ParquetFile(entry["file"])
            for group in range(source.num_row_groups):
                rows += _merge_group(writer, schema, source.read_row_group(group), bag, entry)
    return rows


def _merge_group(writer: Any, schema: Any, table: Any, bag: str, entry: dict[str, Any]) -> int:
    """``table`` (a row group of one bag's table) written with the fleet's key columns."""
    import pyarrow as pa

    n = table.num_rows
    columns = {
        "bag": pa.array([bag] * n, pa.string()),
        "namespace": pa.array([entry["namespace"]] * n, pa.string()),
        "machine": pa.array([entry["machine"]] * n, pa.string()),
    }
    for name in schema.names[3:]:
        columns[name] = table[name] if name in table.column_names else pa.nulls(n, schema.field(name).type)
    writer.write_table(pa.table(columns, schema=schema))
    return n


def fleet_report(results: Sequence[BagResult]) -> dict[str, Any]:
    """Per bag (rows, machines, or its error), per machine kind and per day (rows, bags)."""
    per_machine: dict[str, dict[str, Any]] = {}
    per_day: dict[str, dict[str, Any]] = {}
    bags = []
    for r in results:
        if r.error:
            bags.append({"bag": r.bag, "error": r.error})
            continue
        bags.append(
            {
                "bag": r.bag,
                "rows": sum(t["rows"] for t in r.tables),
                "machines": [f"{t['namespace']} {t['machine']}" for t in r.tables],
            }
        )
        for t in r.tables:
            m = per_machine.setdefault(t["machine"], {"rows": 0, "bags": 0})
            m["rows"] += t["rows"]
            m["bags"] += 1
            for day, count in t["days"].items():
                d = per_day.setdefault(day, {"rows": 0, "bags": set()})
                d["rows"] += count
                d["bags"].add(r.bag)
    return {
        "bags": bags,
        "skipped": sum(1 for r in results if r.error),
        "machines": per_machine,
        "days": {day: {"rows": d["rows"], "bags": len(d["bags"])} for day, d in sorted(per_day.items())},
    }


def run_asbuilt(argv: Sequence[str]) -> int:
    args = parse_args(argv)
    _setup(tuple(args.params))  # a bad --params file stops here, before any bag is read
    try:
        args.output.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise BagError(f"cannot write to {args.output}: {error}") from None
    if args.fleet:
        paths = fleet_bags(args.fleet)
        print(f"{NAME}: {len(paths)} bags", file=sys.stderr)
        results = run_fleet(
            paths,
            args.output,
            args.params,
            args.cell,
            args.workers,
            args.scheduler,
            args.recover,
            args.chunk_seconds,
            args.chunk_margin,
        )
    else:
        results = [
            process_bag(
                p, args.output, args.params, args.cell, args.recover, args.chunk_seconds, args.chunk_margin
            )
            for p in args.bags
        ]
    for r in results:
        if r.error:
            print(f"{NAME}: skipped {r.bag}: {r.error}", file=sys.stderr)
        for t in r.tables:
            print(f"{t['file']}: {t['rows']} rows ({t['namespace']} {t['machine']})")
    report = fleet_report(results)
    grids = [g for r in results for g in r.grids.values()]
    if args.fleet:
        rows = merge_tables(results, args.output / "fleet.parquet")
        report["rows"] = rows
        print(f"{args.output / 'fleet.parquet'}: {rows} rows from {len(results) - report['skipped']} bags")
        if grids:
            merged = AsBuilt.merge(grids)
            grades = [g for r in results for g in r.grade_grids.values()]
            _write_surface(merged, args.output / "fleet_asbuilt", "fleet as-built")
            _write_map(
                merged,
                AsBuilt.merge(grades) if grades else None,
                args.output / "fleet_asbuilt.png",
                "fleet as-built",
            )
        (args.output / "fleet.json").write_text(json.dumps(report, indent=2), encoding="utf-8")
    if all(r.error for r in results):
        raise BagError("no bag could be read")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    return guarded(NAME, run_asbuilt, argv)


if __name__ == "__main__":
    raise SystemExit(main())
