"""``mk_calibrate``: the measure-up of a hydraulic-family machine (issue 33, docs/calibration.md).

``mk_calibrate MACHINE.yaml MEASURED.csv -o CALIBRATED.yaml --report REPORT.json [--png RES.png]``
fits the machine to total-station points (:mod:`manipulator_kinematics.hydraulic.calibration`) and
writes the calibrated machine file (pins, link lengths, zero offsets) and a JSON report.

``mk_calibrate CALIBRATED.yaml --predict POSES.csv --report REPORT.json -o PREDICTED.csv`` writes
the points the calibrated machine predicts, in the instrument frame of that calibration (the
report's ``instrument_from_base``, read, never written here): the control-point check.

MEASURED.csv: header ``pose,<actuators, as the machine's joint_states names>,point,x,y,z[,sigma]``,
one row per measured point. Bad input is refused with one line naming the row and the column.

CALIBRATED.yaml keeps every other section of MACHINE.yaml as it is (the CET200's ``excavator``
section: the excavator nodes load the calibrated file and apply its zero offsets, as the family's
do). A registered machine that reads the file but refuses it is named on stderr, with its reason.
``--hold-offsets`` holds the cylinders' zero offsets at the file's values, for sensors zeroed on
the machine instead.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from manipulator_kinematics.hydraulic.calibration import (
    LEFT,
    RIGHT,
    TIP,
    Calibration,
    CalibrationError,
    Measurements,
    calibrate,
)
from manipulator_kinematics.hydraulic.description import SECTION, Description, read
from manipulator_kinematics.hydraulic.model import HydraulicModel, StrokeError
from manipulator_kinematics.param_files import ConfigError, dump_parameters, load_parameters, open_input
from manipulator_kinematics.registry import machines_described

__all__ = ["main", "predict", "read_points", "report", "write_machine"]

#: Default 1-sigma per coordinate of a total-station point (m) where the CSV has no sigma column.
SIGMA = 0.002


def _point_name(name: str, description: Description) -> str | None:
    """The point a CSV name means: tip, a corner, a pin, or a pin named with a ``_pin`` suffix."""
    pins = {pin for pins in description.bodies.values() for pin in pins}
    if name in (TIP, LEFT, RIGHT) or name in pins:
        return name
    if name.endswith("_pin") and name[: -len("_pin")] in pins:
        return name[: -len("_pin")]
    return None


#: A measure-up has tens to a few thousand rows; a larger file (or a FIFO, a device) is refused
#: before it is read, as every file input of the package (docs/architecture.md).
MAX_INPUT_BYTES = 4 << 20


def _text(path: Path) -> str:
    """The UTF-8 text of an input file, within MAX_INPUT_BYTES (ConfigError naming the file)."""
    with open_input(path, MAX_INPUT_BYTES) as stream:
        data = stream.read(MAX_INPUT_BYTES + 1)
    if len(data) > MAX_INPUT_BYTES:
        raise ConfigError(f"{path}: more than the {MAX_INPUT_BYTES >> 20} MiB such a file may have")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not UTF-8 text") from None


def read_points(path: Path, description: Description, with_xyz: bool = True) -> Measurements:
    """The rows of a MEASURED.csv (``with_xyz``) or POSES.csv; CalibrationError names row and column."""
    actuators = list(description.actuator_names)
    want = ["pose", *actuators, "point"] + (["x", "y", "z"] if with_xyz else [])
    rows = list(csv.reader(io.StringIO(_text(path), newline="")))
    if not rows:
        raise CalibrationError(f"{path}: empty (expected the header {','.join(want)})")
    header = [h.strip() for h in rows[0]]
    optional = ["sigma"] if with_xyz else []
    if header[: len(want)] != want or any(h not in optional for h in header[len(want) :]):
        k = next((i for i, (h, w) in enumerate(zip(header, want, strict=False)) if h != w), len(want))
        got = header[k] if k < len(header) else "(nothing)"
        expected = want[k] if k < len(want) else "nothing or sigma"
        other = " (a CSV of another machine?)" if k in range(1, len(actuators) + 1) else ""
        raise CalibrationError(
            f"{path} row 1, column {k + 1}: {got!r}, expected {expected!r}{other}; {description.name}'s "
            f"header is {','.join(want)}{',sigma' if with_xyz else ''}"
        )
    pose, readings, point, xyz, sigma = [], [], [], [], []
    seen: dict[str, tuple[int, list[float]]] = {}
    for r, row in enumerate(rows[1:], start=2):
        if not any(cell.strip() for cell in row):
            continue
        if len(row) != len(header):
            raise CalibrationError(f"{path} row {r}: {len(row)} columns, the header has {len(header)}")
        values = dict(zip(header, (c.strip() for c in row), strict=True))

        def number(column: str, values: dict[str, str] = values, r: int = r) -> float:
            try:
                value = float(values[column])
            except ValueError:
                raise CalibrationError(
                    f"{path} row {r}, column {column}: {values[column]!r} is not a number"
                ) from None
            if not math.isfinite(value):
                raise CalibrationError(f"{path} row {r}, column {column}: {values[column]} is not finite")
            return value

        reading = [number(a) for a in actuators]
        name = _point_name(values["point"], description)
        if name is None:
            raise CalibrationError(
                f"{path} row {r}, column point: unknown point {values['point']!r} (tip, left_corner, "
                f"right_corner or a pin of {description.name})"
            )
        label = values["pose"]
        if label in seen and not np.allclose(seen[label][1], reading, rtol=0.0, atol=1e-9):
            column = actuators[int(np.argmax(np.abs(np.subtract(seen[label][1], reading))))]
            raise CalibrationError(
                f"{path} row {r}, column {column}: pose {label!r} read differently on row {seen[label][0]}"
            )
        seen.setdefault(label, (r, reading))
        pose.append(label)
        readings.append(reading)
        point.append(name)
        if with_xyz:
            xyz.append([number(c) for c in "xyz"])
            s = number("sigma") if "sigma" in values else SIGMA
            if s <= 0.0:
                raise CalibrationError(f"{path} row {r}, column sigma: {s} must be positive")
            sigma.append(s)
    if not pose:
        raise CalibrationError(f"{path}: no rows after the header")
    n = len(pose)
    return Measurements(
        tuple(pose),
        np.array(readings),
        tuple(point),
        np.array(xyz) if with_xyz else np.full((n, 3), np.nan),
        np.array(sigma) if with_xyz else np.full(n, SIGMA),
        sigma_given="sigma" in header,
    )


def _distances(errors: np.ndarray) -> dict[str, float]:
    d = np.linalg.norm(errors, axis=-1)
    return {"rms": float(np.sqrt(np.mean(d * d))), "max": float(np.max(d)), "n": len(d)}


def report(cal: Calibration, machine: Path, measured: Path, widened: Sequence[str] = ()) -> dict[str, Any]:
    """The REPORT.json content (docs/calibration.md explains every entry)."""
    g, data = cal.geometry, cal.measurements
    names = np.array(data.point)
    poses = np.array(data.pose)
    fit, drawing = _distances(cal.residuals), _distances(cal.drawing_residuals)
    parameters = []
    for k, p in enumerate(g.parameters):
        share = cal.held_share[k]
        status = (
            "held: " + p.held
            if p.held
            else "fitted"
            if share < 1e-6
            else "held: not observable"
            if share > 1.0 - 1e-6
            else f"fitted, {100 * share:.0f}% of it in not-observable combinations (held at the drawing)"
        )
        if p.name.startswith("instrument."):
            continue
        parameters.append(
            {
                "name": p.name,
                "value": float(cal.values[k]),
                "std": float(cal.std[k]),
                "drawing": p.drawing,
                "change": float(cal.values[k] - p.drawing),
                "status": status,
            }
        )
    worst = max(
        parameters, key=lambda q: abs(q["change"]) if q["name"].startswith(("bodies", "links")) else 0
    )
    lines = [
        f"Measure-up of {g.description.name} from {measured.name}: {len(set(data.pose))} poses, "
        f"{len(names)} points.",
        f"Residuals (3-D distance): rms {1000 * fit['rms']:.1f} mm, max {1000 * fit['max']:.1f} mm "
        f"(the drawing, best placed: rms {1000 * drawing['rms']:.1f} mm, "
        f"max {1000 * drawing['max']:.1f} mm).",
        f"Largest pin change: {worst['name']} by {1000 * worst['change']:+.1f} mm.",
        "Zero offsets (true = reading + offset): "
        + ", ".join(
            f"{q['name'].split('.')[1]} {q['value']:+.4f} ± {q['std']:.4f}"
            for q in parameters
            if q["name"].endswith("zero_offset") and q["name"].startswith("cylinders")
        )
        + " m.",
    ]
    if cal.not_observable:
        lines.append(
            f"{len(cal.not_observable)} parameter combinations not determined by these data, held "
            "at the drawing (see not_observable for what would determine them)."
        )
    # A 3-D distance of three sigma-sized errors exceeds 5 sigma * sqrt(3) by chance ~1e-5 of the time.
    distance = np.linalg.norm(cal.residuals, axis=1)
    bad = np.flatnonzero(distance > 5.0 * data.sigma * math.sqrt(3.0))
    lines.append(
        "Check these shots (residual above 5 sigma): "
        + ", ".join(f"{poses[k]} {names[k]} ({1000 * distance[k]:.1f} mm)" for k in bad[:8])
        + (" ..." if len(bad) > 8 else "")
        if len(bad)
        else "No residual above 5 sigma."
    )
    lines.extend(widened)
    return {
        "machine": str(machine),
        "measured": str(measured),
        "instrument_from_base": cal.instrument_from_base.tolist(),
        "instrument_from_base_std": {
            p.name: float(cal.std[k]) for k, p in enumerate(g.parameters) if p.name.startswith("instrument.")
        },
        "parameters": parameters,
        "residuals": {
            **fit,
            "per_point": {n: _distances(cal.residuals[names == n]) for n in sorted(set(names))},
            "per_pose": {p: _distances(cal.residuals[poses == p]) for p in dict.fromkeys(data.pose)},
        },
        "drawing_residuals": drawing,
        "not_observable": cal.not_observable,
        "held": cal.held,
        "fit": cal.cost,
        "limits_widened": list(widened),
        "summary": "\n".join(lines),
    }


def write_machine(cal: Calibration, machine: Path, out: Path) -> list[str]:
    """The machine file with the calibrated pins, link lengths and zero offsets (its other sections
    as they are); checked by loading it (HydraulicModel.from_file) before it replaces ``out``. A
    main-chain joint whose range over the stroke box (5 points per stroke, as the loader checks)
    now leaves its limits gets them widened by 0.5 deg beyond the range (the as-built linkage
    reaches further than the drawing's); returned, one line each, for the report."""
    g = cal.geometry
    d = g.description
    axes = [np.linspace(lo, hi, 5) for lo, hi in zip(d.lower, d.upper, strict=True)]
    if d.swing:
        axes[0] = np.array([d.reference[0]])
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
    theta = g.joints(cal.values, np.concatenate((d.reference[None], grid)))
    widened = []
    document = yaml.safe_load(machine.read_text())
    section = document["/**"]["ros__parameters"][SECTION]
    for k, p in enumerate(cal.geometry.parameters):
        keys = p.name.split(".")
        value = round(float(cal.values[k]), 9)
        if keys[0] == "bodies":
            section["bodies"][keys[1]]["pins"][keys[3]]["xz".index(keys[4])] = value
        elif keys[0] == "links" and keys[1] in section.get("links", {}):
            section["links"][keys[1]]["length"] = value
        elif keys[0] == "links":  # a two-pin body written as a link: its x-axis pin at (length, 0)
            pins = section["bodies"][keys[1]]["pins"]
            pins[next(pin for pin, xz in pins.items() if any(xz))] = [value, 0.0]
        elif keys[0] == "cylinders":
            section["cylinders"][keys[1]]["zero_offset"] = value
        elif keys[0] == "swing":
            section["swing"]["zero_offset"] = value
        elif keys[0] == "tool":
            section["tool"]["width"] = value
        elif keys[0] == "prismatic" and keys[2] == "axis_point":
            section["prismatic"][keys[1]]["axis_point"]["xz".index(keys[3])] = value
        elif keys[0] == "prismatic":
            section["prismatic"][keys[1]]["offset"] = value
    margin = math.radians(0.5)
    for i, joint in enumerate(d.joints):
        if joint.slide is not None:
            continue
        lo, hi = float(np.min(theta[:, i])), float(np.max(theta[:, i]))
        limits = [min(joint.lower, lo - margin), max(joint.upper, hi + margin)]
        if limits != [joint.lower, joint.upper]:
            section["chain"][joint.name]["limits"] = [round(v, 10) for v in limits]
            widened.append(
                f"chain.{joint.name}.limits widened to [{math.degrees(limits[0]):.2f}, "
                f"{math.degrees(limits[1]):.2f}] deg (the as-built range "
                f"[{math.degrees(lo):.2f}, {math.degrees(hi):.2f}] deg)"
            )
    text = (
        f"# {cal.geometry.description.name} as measured up by mk_calibrate from {machine.name} "
        "(docs/calibration.md).\n# true actuator value = sensor reading + zero_offset.\n"
        + dump_parameters(document)
    )
    with tempfile.NamedTemporaryFile("w", suffix=".yaml", dir=out.parent or ".", delete=False) as f:
        f.write(text)
    tmp = Path(f.name)
    try:
        HydraulicModel.from_file(tmp)
    except ConfigError as error:
        tmp.unlink()
        raise CalibrationError(
            f"the calibrated machine file does not load ({error}); nothing written"
        ) from None
    tmp.replace(out)
    return widened


def predict(model: HydraulicModel, instrument_from_base: np.ndarray, poses: Measurements) -> np.ndarray:
    """Each row's point (N, 3) in the instrument frame, from the machine file's model (its zero
    offsets applied to the readings)."""
    D = model.from_readings(poses.readings)
    pins = model.pins(D)
    left, right = model.corners(D)
    points = {**pins, TIP: pins[model.description.tool_pin], LEFT: left, RIGHT: right}
    base = np.array([points[name][k] for k, name in enumerate(poses.point)])
    return base @ instrument_from_base[:3, :3].T + instrument_from_base[:3, 3]


def residual_plot(cal: Calibration, png: Path) -> None:
    """Residual distance per pose and point (mm), the fit against the drawing."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = cal.measurements
    labels = list(dict.fromkeys(data.pose))
    where = {p: i for i, p in enumerate(labels)}
    x = np.array([where[p] for p in data.pose])
    fig, axes = plt.subplots(2, 1, figsize=(12, 6), sharex=True)
    for ax, errors, title in (
        (axes[0], cal.drawing_residuals, "drawing (instrument best placed)"),
        (axes[1], cal.residuals, "calibrated"),
    ):
        d = 1000 * np.linalg.norm(errors, axis=1)
        for k, name in enumerate(sorted(set(data.point))):
            rows = np.array(data.point) == name
            ax.plot(x[rows], d[rows], "osD^v<>ph*Xd"[k % 12], ms=4, color=plt.cm.tab20(k % 20), label=name)
        ax.set_ylabel("3-D residual (mm)")
        ax.set_title(
            f"{cal.geometry.description.name}, {title}: rms "
            f"{1000 * _distances(errors)['rms']:.1f} mm, max {d.max():.1f} mm"
        )
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, ncol=2, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    axes[1].set_xlabel("pose")
    axes[1].set_xticks(range(len(labels)), labels, rotation=90, fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="mk_calibrate",
        description="Measure-up of a hydraulic-family machine (docs/calibration.md): fit its pins, link "
        "lengths, sensor zero offsets and the total station's placement to points measured at known "
        "sensor readings, and write the calibrated machine file and a report; or, with --predict, the "
        "points a calibrated machine predicts in the instrument frame (the control-point check).",
    )
    parser.add_argument("machine", type=Path, help="the machine file (hydraulic_machine section)")
    parser.add_argument(
        "measured", type=Path, nargs="?", help="MEASURED.csv: pose,<actuators>,point,x,y,z[,sigma] (m, rad)"
    )
    parser.add_argument(
        "-o",
        "--output",
        type=Path,
        required=True,
        help="CALIBRATED.yaml to write (or PREDICTED.csv with --predict)",
    )
    parser.add_argument(
        "--report",
        type=Path,
        required=True,
        help="REPORT.json to write (read with --predict, never written then)",
    )
    parser.add_argument(
        "--predict",
        type=Path,
        default=None,
        metavar="POSES.csv",
        help="pose,<actuators>,point rows to predict with a calibrated machine",
    )
    parser.add_argument("--png", type=Path, default=None, help="residuals per pose, a picture to write")
    parser.add_argument(
        "--tolerance",
        type=float,
        default=0.005,
        help="a combination determined worse than this (m, 1 sigma) is held (default 0.005)",
    )
    parser.add_argument(
        "--hold-offsets",
        action="store_true",
        help="hold every cylinder's zero offset at the machine file's value (for sensors zeroed on "
        "the machine rather than offsets in the file)",
    )
    parser.add_argument(
        "--max-evaluations",
        type=int,
        default=200,
        help="residual evaluations before the fit counts as not converged (default 200)",
    )
    args = parser.parse_args(argv)
    try:
        description = read(args.machine)
        if args.predict is not None:
            return _predict(args, description)
        if args.measured is None:
            parser.error("MEASURED.csv is required without --predict")
        data = read_points(args.measured, description)
        hold = {
            f"cylinders.{c.name}.zero_offset": "held by --hold-offsets (sensors zeroed on the machine)"
            for c in description.cylinders
            if args.hold_offsets
        }
        cal = calibrate(description, data, tolerance=args.tolerance, max_nfev=args.max_evaluations, hold=hold)
        widened = write_machine(cal, args.machine, args.output)
        for note in _other_readers(args.output):
            print(f"mk_calibrate: note: {note}", file=sys.stderr)
        content = report(cal, args.machine, args.measured, widened)
        args.report.write_text(json.dumps(content, indent=2) + "\n")
        if args.png is not None:
            residual_plot(cal, args.png)
    except (CalibrationError, ConfigError, StrokeError, OSError, json.JSONDecodeError) as error:
        print(f"mk_calibrate: {error}", file=sys.stderr)
        return 1
    print(content["summary"])
    return 0


def _other_readers(path: Path) -> list[str]:
    """One line per registered machine other than the family's that reads ``path`` (its own
    section beside hydraulic_machine) and refuses it."""
    params = load_parameters(path)
    notes = []
    for key, machine in machines_described(params).items():
        if key == SECTION:
            continue
        try:
            machine.model_of(params)
        except ConfigError as error:
            notes.append(f"the {machine.name} nodes do not load {path}: {error}")
    return notes


def _predict(args: argparse.Namespace, description: Description) -> int:
    report_ = json.loads(_text(args.report))
    T = np.asarray(report_.get("instrument_from_base"), dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise CalibrationError(f"{args.report}: instrument_from_base: expected a 4x4 matrix")
    poses = read_points(args.predict, description, with_xyz=False)
    points = predict(HydraulicModel(description), T, poses)
    with open(args.output, "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["pose", *description.actuator_names, "point", "x", "y", "z"])
        for k in range(len(poses.pose)):
            out.writerow(
                [
                    poses.pose[k],
                    *(f"{v:.9g}" for v in poses.readings[k]),
                    poses.point[k],
                    *(f"{v:.6f}" for v in points[k]),
                ]
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
