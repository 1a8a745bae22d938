"""Write the golden bags of test/data/ from the default machines (see docs/bags.md).

    python scripts/make_golden_bags.py [--output test/data]

Each bag holds the inputs of a forward node along a 2 s motion at 50 Hz and the outputs the
node must publish for them, computed by the numpy core. Regenerate after an intended change of
the kinematics or of the default machines, check the diff of the tests, and commit the bags.
The output is byte-identical for identical inputs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from excavator_kinematics.kinematics import Excavator
from manipulator_kinematics.bag.synthetic import excavator_bag, scara_bag, write_bag
from scara_kinematics.kinematics import Scara

DATA = Path(__file__).resolve().parent.parent / "test" / "data"
SAMPLES = 100
RATE_HZ = 50.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--output", type=Path, default=DATA, help=f"directory (default {DATA})")
    args = parser.parse_args()
    args.output.mkdir(parents=True, exist_ok=True)
    bags = {
        "excavator_forward_golden": excavator_bag(Excavator.default(), SAMPLES, RATE_HZ),
        "scara_forward_golden": scara_bag(Scara.default(), SAMPLES, RATE_HZ),
    }
    for name, topics in bags.items():
        count = write_bag(args.output / name, topics, overwrite=True)
        size = sum(f.stat().st_size for f in (args.output / name).iterdir())
        print(
            f"{args.output / name}: {count} messages on {len(topics)} topics, {size} bytes", file=sys.stderr
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
