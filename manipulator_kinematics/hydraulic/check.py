"""``mk_machine_check MACHINE.yaml``: check a machine file of the hydraulic family before use.

Loads the file (every key validated, the linkage assembled over a coarse grid of the stroke box),
then prints, over a finer grid of the cylinders' stroke box (the swing at its reference): the
smallest dead-centre margin of every dyad and where it occurs, each main-chain joint's range
against its limits, the range of each K diagonal entry (a sign change or a near zero marks a
linkage that stops driving its joint) and the tool's reach; and writes a side-view PNG of the
linkage at every corner of the stroke box (docs/hydraulic_family.md, "Your own machine").

``mk_machine_check OLD.yaml --convert NEW.yaml`` first writes the file in the current form, as
the registered machine whose section it holds reads it (an excavator file of the old form, one
``excavator`` section with the geometry, converted to its ``hydraulic_machine`` and ``excavator``
sections), then checks NEW.yaml.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from manipulator_kinematics.hydraulic.description import SECTION
from manipulator_kinematics.hydraulic.model import HydraulicModel
from manipulator_kinematics.param_files import ConfigError, dump_parameters, load_parameters
from manipulator_kinematics.registry import machines_described

__all__ = ["box_grid", "convert", "main", "report", "side_views"]


def convert(path: Path, out: Path) -> None:
    """Write the machine file ``path`` to ``out`` in the current form: the sections the registered
    machine whose section it holds reads (an old excavator file converted on load), optional keys
    left out where not given; ConfigError names what is wrong."""
    params = load_parameters(path)
    found = machines_described(params)
    if len(found) != 1:
        raise ConfigError(f"expected the file of one registered machine, found sections {sorted(params)}")
    machine = next(iter(found.values()))
    values = machine.values(params, str(path))
    sections = {key: values[key] for key in machine.also}
    sections[machine.section] = {k: v for k, v in values.items() if k not in machine.also}
    text = (
        f"# {path.name} in the current form (mk_machine_check --convert; docs/hydraulic_family.md).\n"
        + dump_parameters({"/**": {"ros__parameters": _given(sections)}})
    )
    out.write_text(text, encoding="utf-8")


def _given(value: object) -> object:
    """Nested values without the optional keys left out (None)."""
    if isinstance(value, dict):
        return {k: _given(v) for k, v in value.items() if v is not None}
    return value


def box_grid(model: HydraulicModel, n: int) -> np.ndarray:
    """States (N, m) on an n-point grid of every cylinder's stroke, faces included, swing at its reference."""
    axes = [np.linspace(lo, hi, n) for lo, hi in zip(model.lower, model.upper, strict=True)]
    if model.swing:
        axes[0] = np.array([model.reference[0]])
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, model.m)


def report(model: HydraulicModel, n: int = 41) -> str:
    """The text :func:`main` prints: margins, joint ranges, K and reach over the stroke box."""
    grid = box_grid(model, n)
    margins = np.degrees(model.margins(grid))
    theta = model.joints(grid)
    k = model.k_matrix(grid)
    Q = model.pose(grid)
    d = model.description
    lines = [f"{d.name}: {len(grid)} states on a {n}-point grid of the stroke box (swing at its reference)"]
    lines.append("dead-centre margin per dyad (deg; 0 = dead centre):")
    for i, name in enumerate(model.dyad_names):
        at = grid[np.argmin(margins[:, i])]
        lines.append(f"  {name:28s} min {margins[:, i].min():7.2f}  at D = {np.round(at, 4).tolist()}")
    lines.append("main-chain joints over the box (limits):")
    for i, name in enumerate(model.joint_names):
        if model.swing and i == 0:
            continue
        joint = d.joints[i - int(model.swing)]
        scale, unit = (1.0, "m") if joint.slide else (180.0 / np.pi, "deg")
        lines.append(
            f"  {name:8s} {theta[:, i].min() * scale:9.3f} .. {theta[:, i].max() * scale:9.3f} {unit}"
            f"   limits [{joint.lower * scale:.3f}, {joint.upper * scale:.3f}]"
        )
    lines.append("K = dtheta/dD, the entries each cylinder drives (min .. max over the box):")
    for j, actuator in enumerate(model.actuator_names):
        if model.swing and j == 0:
            continue
        for i, name in enumerate(model.joint_names):
            column = k[:, i, j]
            if np.max(np.abs(column)) > 1e-12:
                lines.append(f"  d{name}/d{actuator}: {column.min():9.4f} .. {column.max():9.4f}")
    r = np.hypot(Q[:, 0], Q[:, 1])
    lines.append(
        f"tool {d.tool_pin}: reach {r.min():.3f} .. {r.max():.3f} m, height {Q[:, 2].min():.3f} .. "
        f"{Q[:, 2].max():.3f} m"
    )
    return "\n".join(lines)


def side_views(model: HydraulicModel, path: Path) -> None:
    """A side view (r, z) of the linkage at every corner of the cylinders' stroke box."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = model.description
    first = int(model.swing)
    corners = [
        np.array(([model.reference[0]] if model.swing else []) + list(c))
        for c in itertools.product(*zip(model.lower[first:], model.upper[first:], strict=True))
    ]
    columns = min(4, len(corners))
    rows = -(-len(corners) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 4.0 * rows), squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, D in zip(axes.flat, corners, strict=False):
        pins = model.pins(D)
        t1 = D[0] if model.swing else 0.0
        plane = {name: (p[0] * np.cos(t1) + p[1] * np.sin(t1), p[2]) for name, p in pins.items()}
        for i, (body, body_pins) in enumerate(d.bodies.items()):
            points = np.array([plane[p] for p in body_pins])
            if len(points) > 2:  # the body's outline: its pins in turn about their centre
                centre = points.mean(axis=0)
                points = points[np.argsort(np.arctan2(*(points - centre).T[::-1]))]
                points = np.vstack((points, points[:1]))
            ax.plot(
                points[:, 0], points[:, 1], "-o", color=colours[i % len(colours)], ms=3, lw=1.5, label=body
            )
        for c in d.cylinders:
            ends = np.array([plane[c.base], plane[c.rod]])
            ax.plot(ends[:, 0], ends[:, 1], "-", color="0.3", lw=4, alpha=0.5)
        tool = plane[d.tool_pin]
        ax.plot(*tool, "r*", ms=10)
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_aspect("equal")
        ax.set_title("D = " + ", ".join(f"{v:.3g}" for v in D[first:]), fontsize=9)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(corners) :]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=7, loc="best")
    figure.suptitle(
        f"{d.name}: the linkage at the corners of the stroke box (side view, r right, z up; "
        "grey: cylinders, red star: tool)",
        fontsize=10,
    )
    figure.tight_layout()
    figure.savefig(path, dpi=90)
    plt.close(figure)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="mk_machine_check",
        description="Check a machine file of the hydraulic family (docs/hydraulic_family.md): load "
        "it (every key validated), print the smallest dead-centre margin of every dyad, the joint "
        "ranges, K and the reach over the stroke box, and draw the linkage at the stroke box's "
        "corners.",
    )
    parser.add_argument(
        "machine", type=Path, help="the machine file (ROS 2 parameters file with a hydraulic_machine section)"
    )
    parser.add_argument("--grid", type=int, default=41, help="points per cylinder stroke (default 41)")
    parser.add_argument(
        "--png",
        type=Path,
        default=None,
        help="side-view picture to write (default: <machine file stem>_check.png here)",
    )
    parser.add_argument("--no-png", action="store_true", help="print the report only")
    parser.add_argument(
        "--convert",
        type=Path,
        metavar="NEW.yaml",
        default=None,
        help="first write the file in the current form to NEW.yaml (an excavator file of the old "
        "form: its hydraulic_machine and excavator sections), then check NEW.yaml",
    )
    args = parser.parse_args(argv)
    if args.grid < 2:
        parser.error("--grid: at least 2 points")
    try:
        if args.convert is not None:
            convert(args.machine, args.convert)
            print(f"written: {args.convert}")
            args.machine = args.convert
        elif SECTION not in load_parameters(args.machine):
            raise ConfigError(
                f"no {SECTION!r} section under /**: ros__parameters (an excavator file of the old "
                "form: convert it with --convert NEW.yaml)"
            )
        model = HydraulicModel.from_file(args.machine)
    except (ConfigError, OSError) as error:
        print(f"{args.machine}: {error}", file=sys.stderr)
        return 1
    print(report(model, args.grid))
    if not args.no_png:
        png = args.png or Path(f"{args.machine.stem}_check.png")
        side_views(model, png)
        print(f"side views: {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
