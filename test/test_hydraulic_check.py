"""mk_machine_check: the report of a machine file of the hydraulic family and its side views
(docs/hydraulic_family.md, "Your own machine")."""

from __future__ import annotations

import pytest

from manipulator_kinematics.param_files import config_path


def test_machine_check_prints_margins_ranges_and_draws(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    from manipulator_kinematics.hydraulic.check import main

    png = tmp_path / "loader.png"
    assert main([str(config_path("wheel_loader_wl20.yaml")), "--grid", "11", "--png", str(png)]) == 0
    text = capsys.readouterr().out
    assert "tilt_link_bucket_pin" in text and "theta3" in text and "limits [-102.000, 60.000]" in text
    assert png.stat().st_size > 10_000


def test_machine_check_refuses_a_bad_file_in_one_line(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    from manipulator_kinematics.hydraulic.check import main

    text = config_path("wheel_loader_wl20.yaml").read_text().replace("length: 0.868", "length: 3.0")
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    assert main([str(path), "--no-png"]) == 1
    error = capsys.readouterr().err.strip()
    assert "dyads.tilt_link_bucket_pin: does not close" in error and "\n" not in error
