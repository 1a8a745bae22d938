"""Write the hydraulic family's pictures into docs/images/ from the shipped machine files.

    MPLBACKEND=Agg python scripts/make_family_figures.py [--output docs/images]

For each of wheel_loader and knuckle_crane: ``<name>_motion.gif`` (loader: carry, lift, dump,
return; crane: fold out, lift, telescope, swing) drawn from ``pins()`` through
:func:`manipulator_kinematics.hydraulic.figures.family_gif`, and ``<name>_working_range.png``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from manipulator_kinematics.hydraulic.figures import family_gif, keyframe_motion, working_range
from manipulator_kinematics.registry import machine

#: Keyframes of D and the seconds of each leg (every state inside the stroke box).
MOTIONS = {
    "wheel_loader": (
        "WL20 wheel loader: lift and dump",
        # [lift_cylinder, tilt_cylinder] (m): carry on the ground, lift rolled back, dump, roll
        # back, lower to the ground.
        [[1.30, 1.80], [2.30, 2.02], [2.30, 1.40], [2.30, 1.90], [1.30, 1.70]],
        [4.0, 2.5, 2.0, 3.5],
    ),
    "knuckle_crane": (
        "KC100 knuckle crane: fold, lift, telescope, swing",
        # [swing_joint (rad), lift_cylinder, fold_cylinder, tele_cylinder (m)]: folded, the boom
        # raised enough that the unfolding pin stays above the ground; fold out, lift, telescope
        # out, swing.
        [
            [0.0, 2.20, 1.65, 2.60],
            [0.0, 2.20, 2.45, 2.60],
            [0.0, 2.50, 2.45, 2.60],
            [0.0, 2.50, 2.45, 4.40],
            [1.6, 2.50, 2.45, 4.40],
        ],
        [4.0, 3.0, 3.0, 3.5],
    ),
}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--output", type=Path, default=Path(__file__).resolve().parent.parent / "docs" / "images"
    )
    args = parser.parse_args()
    for name, (title, keys, seconds) in MOTIONS.items():
        arm = machine(name).model()
        D = arm.hydraulic.validate(keyframe_motion(keys, seconds))
        print(family_gif(arm, D, args.output / f"{name}_motion.gif", title))
        print(working_range(arm, args.output / f"{name}_working_range.png", f"{arm.name}: working range"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
