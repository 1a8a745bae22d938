"""Write the golden bags of test/data/ from the default machines (see docs/bags.md).

    python scripts/make_golden_bags.py [--output test/data] [--machines NAME ...]

One bag ``<name>_forward_golden`` per registered machine with a ``synthesize`` hook
(manipulator_kinematics.registry): the inputs of its forward node along a 2 s motion at 50 Hz and
the outputs the node must publish for them, computed by the numpy core. Regenerate after an
intended change of the kinematics or of the default machines, check the diff of the tests, and
commit the bags. The output is byte-identical for identical inputs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from manipulator_kinematics.bag.synthetic import GOLDEN_RATE_HZ, GOLDEN_SAMPLES, golden_name, write_bag
from manipulator_kinematics.registry import machine, machines

DATA = Path(__file__).resolve().parent.parent / "test" / "data"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--output", type=Path, default=DATA, help=f"directory (default {DATA})")
    parser.add_argument(
        "--machines", nargs="+", metavar="NAME", help="only these machines (default: every one with a hook)"
    )
    args = parser.parse_args()
    chosen = [machine(name) for name in args.machines] if args.machines else list(machines().values())
    args.output.mkdir(parents=True, exist_ok=True)
    for m in chosen:
        if m.synthesize is None:
            print(f"{m.name}: no synthesize hook, no golden bag", file=sys.stderr)
            continue
        topics = m.synthesize(m.model(), GOLDEN_SAMPLES, GOLDEN_RATE_HZ)
        path = args.output / golden_name(m.name)
        count = write_bag(path, topics, overwrite=True)
        size = sum(f.stat().st_size for f in path.iterdir())
        print(f"{path}: {count} messages on {len(topics)} topics, {size} bytes", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
