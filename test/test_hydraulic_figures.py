"""The family's pictures (manipulator_kinematics.hydraulic.figures): the keyframe motion passes
every keyframe at rest and stays inside the stroke box, and the working-range diagram is written
with the reach and height the model gives over the box."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from manipulator_kinematics.hydraulic.check import box_grid
from manipulator_kinematics.hydraulic.figures import keyframe_motion, working_range
from manipulator_kinematics.registry import machine


def test_keyframe_motion_rests_at_every_keyframe() -> None:
    keys = [[1.3, 1.8], [2.3, 2.02], [2.3, 1.4]]
    D = keyframe_motion(keys, [2.0, 1.0], rate=20.0)
    assert len(D) == 40 + 20 + 1
    for k, i in ((0, 0), (1, 40), (2, 60)):
        np.testing.assert_allclose(D[i], keys[k], atol=1e-12)
    steps = np.abs(np.diff(D, axis=0))
    assert np.all(steps[[0, 39, 40, 59]] < 0.1 * steps.max())  # slow at the keyframes (eased)
    lo, hi = np.min(keys, axis=0), np.max(keys, axis=0)
    assert np.all(D - lo >= -1e-12) and np.all(hi - D >= -1e-12)  # between the keyframes: never beyond


def test_working_range_png(tmp_path: Path) -> None:
    arm = machine("wheel_loader").model()
    path = working_range(arm, tmp_path / "range.png", "WL20", n=9)
    with Image.open(path) as image:
        assert image.size == (640, 480)
        pixels = np.asarray(image.convert("L"), dtype=float)
    assert pixels.std() > 5.0  # something is drawn
    Q = arm.hydraulic.pose(box_grid(arm.hydraulic, 9))
    assert Q[:, 0].max() > Q[:, 0].min() and Q[:, 2].max() > Q[:, 2].min()
