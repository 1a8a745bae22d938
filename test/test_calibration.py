"""Measure-up calibration (issue 33): synthetic as-built machines measured by a total station.

The as-built machine is a perturbed machine file solved by HydraulicModel (not by the calibration's
own forward solve); its points are turned into a tilted, displaced instrument frame here with
scipy's Rotation, and the sensors read true - offset. The calibration sees only the CSV."""

from __future__ import annotations

import copy
import csv
import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from manipulator_kinematics.hydraulic import HydraulicModel, parse, read
from manipulator_kinematics.hydraulic.calibration import CalibrationError, Geometry, calibrate
from manipulator_kinematics.hydraulic.measure_up import main, read_points
from manipulator_kinematics.param_files import ConfigError, config_path, load_parameters

FILES = {
    "CET200": "excavator_cet200.yaml",
    "WL20": "wheel_loader_wl20.yaml",
    "KC100": "knuckle_crane_kc100.yaml",
}
EDGE = ["tip", "left_corner", "right_corner"]
DEG = np.pi / 180.0


def _section(name: str) -> dict:
    return copy.deepcopy(load_parameters(config_path(FILES[name]))["hydraulic_machine"])


def as_built(
    name: str, rng: np.random.Generator, swing_offset: float = 0.5 * DEG
) -> tuple[dict, HydraulicModel]:
    """The drawing with every pin not defining a frame moved by 1-3 cm (random direction), link
    lengths by 1-3 cm, cylinder zero offsets of 1-2 cm and the swing's of ``swing_offset``; drawn
    again where the CET200's bucket linkage, near a dead centre at a stroke corner, would not
    assemble over the whole box (a machine that does not assemble is not built)."""
    for _ in range(20):
        try:
            return _as_built(name, rng, swing_offset)
        except ConfigError:
            continue
    raise AssertionError("no as-built machine assembles")


def _as_built(name: str, rng: np.random.Generator, swing_offset: float) -> tuple[dict, HydraulicModel]:
    section = _section(name)
    held = {q.name for q in Geometry(read(config_path(FILES[name]))).parameters if q.held}
    for body, entry in section["bodies"].items():
        for pin, xz in entry["pins"].items():
            angle = rng.uniform(0, 2 * np.pi)
            move = rng.uniform(0.01, 0.03) * np.array([np.cos(angle), np.sin(angle)])
            # the coordinates that define a frame (the gauges) stay: the truth in the fit's frames
            keep = [f"bodies.{body}.pins.{pin}.{a}" in held for a in "xz"]
            entry["pins"][pin] = np.where(keep, xz, np.asarray(xz) + move).tolist()
    for link in section.get("links", {}).values():
        link["length"] += rng.choice([-1, 1]) * rng.uniform(0.01, 0.03)
    for cylinder in section["cylinders"].values():
        cylinder["zero_offset"] = float(rng.choice([-1, 1]) * rng.uniform(0.01, 0.02))
    if section["tool"]["width"] > 0.0:  # a cutting edge as built; a crane's rotator has none
        section["tool"]["width"] += float(rng.choice([-1, 1]) * rng.uniform(0.01, 0.03))
    for slide in section.get("prismatic", {}).values():  # the telescope's line off its drawing
        slide["axis_point"][1] += float(rng.choice([-1, 1]) * rng.uniform(0.01, 0.03))
    if "swing" in section:
        section["swing"]["zero_offset"] = swing_offset
    for joint in section["chain"].values():  # the as-built linkage may reach further than the drawing's
        joint["limits"] = [joint["limits"][0] - 0.5, joint["limits"][1] + 0.5]
    return section, HydraulicModel(parse(section))


def instrument(rng: np.random.Generator) -> np.ndarray:
    """instrument_from_base: a heading, 2-4 degrees of tilt, 8-15 m away."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler(
        "ZYX", [rng.uniform(-np.pi, np.pi), rng.uniform(2, 4) * DEG, -rng.uniform(2, 4) * DEG]
    ).as_matrix()
    T[:3, 3] = [rng.uniform(8, 15), rng.uniform(-15, -8), rng.uniform(-2, 2)]
    return T


def poses(model: HydraulicModel, rng: np.random.Generator, n: int) -> np.ndarray:
    """n true states spread over the strokes (stratified per cylinder), swing at 3 headings."""
    D = np.empty((n, model.m))
    for i in range(model.m):
        lo, hi = model.lower[i] + 0.01, model.upper[i] - 0.01
        D[:, i] = lo + (hi - lo) * (rng.permutation(n) + rng.uniform(size=n)) / n
    if model.swing:
        D[:, 0] = np.array([-1.3, 0.2, 1.6])[np.arange(n) % 3]
    return D


def measure(
    model: HydraulicModel,
    T: np.ndarray,
    D: np.ndarray,
    names: list[str],
    rng: np.random.Generator,
    noise: float,
) -> list[list]:
    """CSV rows: pose, readings (true - offset), point, x, y, z in the instrument frame."""
    pins = model.pins(D)
    left, right = model.corners(D)
    points = {**pins, "tip": pins[model.description.tool_pin], "left_corner": left, "right_corner": right}
    readings = model.to_readings(D)
    rows = []
    for k in range(len(D)):
        for name in names:
            xyz = T[:3, :3] @ points[name][k] + T[:3, 3] + rng.normal(0.0, noise, 3)
            rows.append([f"p{k:02d}", *map(float, readings[k]), name, *map(float, xyz)])
    return rows


def write_csv(path: Path, model: HydraulicModel, rows: list[list], xyz: bool = True) -> Path:
    with open(path, "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["pose", *model.actuator_names, "point"] + (["x", "y", "z"] if xyz else []))
        for row in rows:
            out.writerow([repr(v) if isinstance(v, float) else v for v in (row if xyz else row[:-3])])
    return path


def test_forward_solve_equals_the_model() -> None:
    """The calibration's position-only solve at the drawing is HydraulicModel's, every pin."""
    for file in [*FILES.values(), "knuckle_crane_kc100.yaml"]:
        model = HydraulicModel.from_file(config_path(file))
        g = Geometry(model.description)
        D = poses(model, np.random.default_rng(3), 7)
        ours = g.base_points(g.drawing, D)
        pins = model.pins(D)
        left, right = model.corners(D)
        for name, xyz in pins.items():
            np.testing.assert_allclose(ours[name], xyz, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(ours["left_corner"], left, atol=1e-12)
        np.testing.assert_allclose(ours["right_corner"], right, atol=1e-12)


@pytest.mark.parametrize("name", FILES)
def test_measure_up_predicts_held_out_poses(name: str, tmp_path: Path) -> None:
    """Tip and corners at 36 poses, 2 mm noise: the calibrated file predicts 30 other poses within
    RMS 3 mm / max 10 mm where the drawing (with the instrument placed by the calibration) is off
    by decimetres; mk_calibrate --predict gives the numbers from the written files alone."""
    rng = np.random.default_rng(33)
    _, truth = as_built(name, rng)
    T = instrument(rng)
    measured = write_csv(
        tmp_path / "measured.csv", truth, measure(truth, T, poses(truth, rng, 36), EDGE, rng, 0.002)
    )
    machine = config_path(FILES[name])
    out, rep, png = tmp_path / "calibrated.yaml", tmp_path / "report.json", tmp_path / "residuals.png"
    assert main([str(machine), str(measured), "-o", str(out), "--report", str(rep), "--png", str(png)]) == 0
    HydraulicModel.from_file(out)  # a valid machine file of the family
    report = json.loads(rep.read_text())
    assert report["residuals"]["rms"] < 0.005 and set(report["residuals"]["per_point"]) == set(EDGE)
    assert len(report["residuals"]["per_pose"]) == 36 and png.stat().st_size > 10_000
    assert np.asarray(report["instrument_from_base"]).shape == (4, 4) and report["summary"]

    held = measure(truth, T, poses(truth, rng, 30), EDGE, rng, 0.0)
    write_csv(tmp_path / "poses.csv", truth, held, xyz=False)
    predicted = tmp_path / "predicted.csv"
    before = rep.read_text()
    assert (
        main([str(out), "--predict", str(tmp_path / "poses.csv"), "--report", str(rep), "-o", str(predicted)])
        == 0
    )
    assert rep.read_text() == before  # read, never written
    with open(predicted) as f:
        got = np.array([[float(r["x"]), float(r["y"]), float(r["z"])] for r in csv.DictReader(f)])
    error = np.linalg.norm(got - np.array([r[-3:] for r in held], dtype=float), axis=1)
    assert np.sqrt(np.mean(error**2)) <= 0.003 and error.max() <= 0.010, (
        np.sqrt(np.mean(error**2)),
        error.max(),
    )

    # The drawing, placed as the calibration placed the instrument, misses by decimetres.
    drawing = HydraulicModel.from_file(machine)
    readings = np.array([r[1 : 1 + drawing.m] for r in held[::3]], dtype=float)
    T_fit = np.asarray(report["instrument_from_base"])
    tips = drawing.pins(np.clip(readings, drawing.lower, drawing.upper))[drawing.description.tool_pin]
    miss = np.linalg.norm(
        tips @ T_fit[:3, :3].T + T_fit[:3, 3] - np.array([r[-3:] for r in held[::3]], dtype=float), axis=1
    )
    assert miss.max() > 0.1, miss.max()


def _parameters_of(section: dict, g: Geometry, T: np.ndarray) -> np.ndarray:
    """The truth in the calibration's parameter vector."""
    p = g.drawing.copy()
    for k, q in enumerate(g.parameters):
        keys = q.name.split(".")
        if keys[0] == "bodies":
            p[k] = section["bodies"][keys[1]]["pins"][keys[3]]["xz".index(keys[4])]
        elif keys[0] == "links":
            p[k] = section["links"][keys[1]]["length"]
        elif keys[0] in ("cylinders", "swing"):
            p[k] = (section[keys[0]][keys[1]] if keys[0] == "cylinders" else section["swing"])["zero_offset"]
        elif keys[0] == "tool":
            p[k] = section["tool"]["width"]
        elif keys[0] == "prismatic" and keys[2] == "axis_point":
            p[k] = section["prismatic"][keys[1]]["axis_point"]["xz".index(keys[3])]
    rv = Rotation.from_matrix(T[:3, :3]).as_rotvec()
    for k, a in enumerate("xyz"):
        p[g.index[f"instrument.r{a}"]], p[g.index[f"instrument.t{a}"]] = rv[k], T[k, 3]
    return p


@pytest.mark.parametrize(
    "name", ["WL20", *(pytest.param(n, marks=pytest.mark.slow) for n in ("CET200", "KC100"))]
)
def test_noise_free_points_on_every_pin_recover_every_parameter(name: str) -> None:
    """Noise-free tip, corners and every pin: nothing is not observable, and every parameter (pins,
    link lengths, zero offsets, the instrument's 6 DoF) comes back to 1e-6."""
    rng = np.random.default_rng(7)
    section, truth = as_built(name, rng, swing_offset=0.0)  # the swing zero is the heading's gauge
    T = instrument(rng)
    pins = sorted({p for b in section["bodies"].values() for p in b["pins"]})
    description = read(config_path(FILES[name]))
    rows = measure(truth, T, poses(truth, rng, 24), EDGE + pins, rng, 0.0)
    data = read_points_rows(rows, truth, description)
    cal = calibrate(description, data)
    assert cal.not_observable == []
    expected = _parameters_of(section, cal.geometry, T)
    worst = np.argmax(np.abs(cal.values - expected))
    assert np.abs(cal.values - expected).max() < 1e-6, cal.geometry.parameters[worst].name
    np.testing.assert_allclose(cal.instrument_from_base, T, atol=1e-6)


def read_points_rows(rows: list[list], model: HydraulicModel, description, path: Path | None = None):
    """Measurements of rows through the CSV reader."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        return read_points(write_csv(Path(tmp) / "m.csv", model, rows), description)


def test_tip_points_alone_leave_offsets_against_pins_unobservable() -> None:
    """With tip and corners only, a cylinder's zero offset against moving its pin along the
    cylinder is named, held, and a point on that cylinder's pins is what would determine it."""
    rng = np.random.default_rng(5)
    _, truth = as_built("CET200", rng)
    description = read(config_path(FILES["CET200"]))
    data = read_points_rows(
        measure(truth, instrument(rng), poses(truth, rng, 36), EDGE, rng, 0.002), truth, description
    )
    cal = calibrate(description, data)
    boom = [e for e in cal.not_observable if "cylinders.boom_cylinder.zero_offset" in e["combination"]]
    assert boom, [e["combination"] for e in cal.not_observable]
    assert any("boom_cyl" in s for e in boom for s in e["would_determine"])
    exact = [e["combination"] for e in cal.not_observable if e["kind"] == "gauge (exact)"]
    # the boom cylinder's two pins turned together about the boom foot: nothing measured moves
    assert any("boom_cyl_rod" in c and "boom_cyl_base" in c for c in exact), exact
    held = {h["parameter"] for h in cal.held}
    assert {"swing.zero_offset", "bodies.upper_structure.pins.boom_foot.z"} <= held
    assert cal.held_share[cal.geometry.index["cylinders.boom_cylinder.zero_offset"]] > 0.1


def test_pins_named_with_a_pin_suffix(tmp_path: Path) -> None:
    """The issue's names: arm_pin and bucket_pin are pins of the file, boom_foot_pin is boom_foot."""
    truth, rows = _good_rows(np.random.default_rng(6))
    rows = [
        [*r[:5], name, *r[6:]]
        for r, name in zip(rows, ["arm_pin", "bucket_pin", "boom_foot_pin"], strict=False)
    ]
    data = read_points(write_csv(tmp_path / "m.csv", truth, rows), read(config_path(FILES["CET200"])))
    assert data.point == ("arm_pin", "bucket_pin", "boom_foot")


def _good_rows(rng: np.random.Generator) -> tuple[HydraulicModel, list[list]]:
    _, truth = as_built("CET200", rng)
    return truth, measure(truth, instrument(rng), poses(truth, rng, 12), EDGE, rng, 0.002)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            lambda rows: rows[4].__setitem__(5, "bucket_tooth"),
            r"row 6, column point: unknown point 'bucket_tooth'",
        ),
        (lambda rows: rows[2].__setitem__(3, "nan"), r"row 4, column arm_cylinder: nan is not finite"),
        (lambda rows: rows[7].__setitem__(7, "x"), r"row 9, column y: 'x' is not a number"),
        (
            lambda rows: rows[1].__setitem__(2, 2.5),
            r"row 3, column boom_cylinder: pose 'p00' read differently",
        ),
        (lambda rows: rows.__delitem__(slice(9, None)), r"too few poses"),
    ],
)
def test_bad_rows_refused_naming_row_and_column(
    edit, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    truth, rows = _good_rows(np.random.default_rng(1))
    rows = [list(r) for r in rows]
    edit(rows)
    measured = write_csv(tmp_path / "m.csv", truth, rows)
    out = tmp_path / "c.yaml"
    assert (
        main(
            [
                str(config_path(FILES["CET200"])),
                str(measured),
                "-o",
                str(out),
                "--report",
                str(tmp_path / "r.json"),
            ]
        )
        == 1
    )
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and re.search(message, err), err
    assert not out.exists() and not (tmp_path / "r.json").exists()


def test_a_csv_of_another_machine_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(2)
    _, loader = as_built("WL20", rng)
    measured = write_csv(
        tmp_path / "m.csv", loader, measure(loader, instrument(rng), poses(loader, rng, 12), EDGE, rng, 0.002)
    )
    assert (
        main(
            [
                str(config_path(FILES["CET200"])),
                str(measured),
                "-o",
                str(tmp_path / "c.yaml"),
                "--report",
                str(tmp_path / "r.json"),
            ]
        )
        == 1
    )
    err = capsys.readouterr().err.strip()
    assert "row 1, column 2: 'lift_cylinder', expected 'swing_joint' (a CSV of another machine?)" in err, err
    assert len(err.splitlines()) == 1


def test_an_unknown_actuator_column_is_refused(tmp_path: Path) -> None:
    measured = tmp_path / "m.csv"
    measured.write_text("pose,swing_joint,boom_cylindr,arm_cylinder,bucket_cylinder,point,x,y,z\n")
    with pytest.raises(CalibrationError, match=r"row 1, column 3: 'boom_cylindr', expected 'boom_cylinder'"):
        read_points(measured, read(config_path(FILES["CET200"])))


def test_a_fit_that_does_not_converge_says_so_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    truth, rows = _good_rows(np.random.default_rng(4))
    measured = write_csv(tmp_path / "m.csv", truth, rows)
    out, rep = tmp_path / "c.yaml", tmp_path / "r.json"
    assert (
        main(
            [
                str(config_path(FILES["CET200"])),
                str(measured),
                "-o",
                str(out),
                "--report",
                str(rep),
                "--max-evaluations",
                "2",
            ]
        )
        == 1
    )
    assert "did not converge" in capsys.readouterr().err
    assert not out.exists() and not rep.exists()
    with pytest.raises(CalibrationError, match="did not converge"):
        calibrate(
            read(config_path(FILES["CET200"])),
            read_points(measured, read(config_path(FILES["CET200"]))),
            max_nfev=2,
        )


def test_a_machine_far_from_its_drawing_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A bucket 0.5 m longer than the drawing's (another bucket on the machine): the fit stops at
    its bound and writes nothing."""
    rng = np.random.default_rng(8)
    section, _ = as_built("WL20", rng)
    section["bodies"]["bucket"]["pins"]["cutting_edge"][0] += 0.5
    truth = HydraulicModel(parse(section))
    pins = ["bucket_hinge", "lift_cyl_rod", "tilt_cyl_base", "tilt_cyl_rod", "bell_crank_pivot"]
    rows = measure(truth, instrument(rng), poses(truth, rng, 16), EDGE + pins, rng, 0.002)
    out = tmp_path / "c.yaml"
    code = main(
        [
            str(config_path(FILES["WL20"])),
            str(write_csv(tmp_path / "m.csv", truth, rows)),
            "-o",
            str(out),
            "--report",
            str(tmp_path / "r.json"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 1 and "drawing or data wrong; nothing written" in err, err
    assert not out.exists()


def test_the_calibrated_file_keeps_strokes_and_adds_offsets(tmp_path: Path) -> None:
    """CALIBRATED.yaml: same keys as the drawing's plus zero_offset, strokes unchanged."""
    rng = np.random.default_rng(9)
    _, truth = as_built("WL20", rng)
    measured = write_csv(
        tmp_path / "m.csv", truth, measure(truth, instrument(rng), poses(truth, rng, 30), EDGE, rng, 0.002)
    )
    out = tmp_path / "c.yaml"
    assert (
        main(
            [
                str(config_path(FILES["WL20"])),
                str(measured),
                "-o",
                str(out),
                "--report",
                str(tmp_path / "r.json"),
            ]
        )
        == 0
    )
    new = yaml.safe_load(out.read_text())["/**"]["ros__parameters"]["hydraulic_machine"]
    old = _section("WL20")
    for name, cylinder in old["cylinders"].items():
        for key in ("min_length", "max_length", "reference_length"):
            assert new["cylinders"][name][key] == cylinder[key]
        assert abs(new["cylinders"][name]["zero_offset"]) < 0.2


def test_an_input_that_is_no_regular_file_or_too_large_is_refused_in_one_line(tmp_path: Path, capsys) -> None:
    import os

    fifo = tmp_path / "measured.csv"
    os.mkfifo(fifo)
    big = tmp_path / "big.csv"
    with open(big, "wb") as f:
        f.truncate(5 << 20)
    machine = str(config_path("wheel_loader_wl20.yaml"))
    for path, reason in ((fifo, "a FIFO, not a regular file"), (big, "more than the 4 MiB")):
        code = main(
            [machine, str(path), "-o", str(tmp_path / "c.yaml"), "--report", str(tmp_path / "r.json")]
        )
        err = capsys.readouterr().err
        assert code == 1 and reason in err and err.count("\n") == 1, err
        assert not (tmp_path / "c.yaml").exists()


def test_std_without_a_sigma_column_is_scaled_by_the_residuals_scatter() -> None:
    """With sigmas from the CSV the standard deviations take them as given; with the default sigma
    (no column) they are scaled by sqrt(chi2/dof), as curve_fit does without absolute_sigma. Noise
    of 4 mm against the default 2 mm: chi2/dof near 4, every std twice the unscaled one."""
    rng = np.random.default_rng(11)
    _, truth = as_built("WL20", rng)
    description = read(config_path(FILES["WL20"]))
    rows = measure(truth, instrument(rng), poses(truth, rng, 36), EDGE, rng, 0.004)
    data = read_points_rows(rows, truth, description)
    assert not data.sigma_given
    scaled = calibrate(description, data)
    given = calibrate(description, dataclasses.replace(data, sigma_given=True))
    chi2 = scaled.cost["chi2_per_dof"]
    assert 2.5 < chi2 < 6.0 and scaled.cost["std_scaled_by_chi2"] and not given.cost["std_scaled_by_chi2"]
    fitted = given.std > 0
    np.testing.assert_allclose(scaled.std[fitted], np.sqrt(chi2) * given.std[fitted], rtol=1e-9)
