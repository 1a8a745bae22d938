"""The shipped artefacts on a CPU without numpy's optional features: the URDFs (urdf/) and the
golden bags (test/data/) regenerated in a subprocess with every dispatched SIMD feature that
this CPU has switched off (NPY_DISABLE_CPU_FEATURES, numpy's runtime dispatch) must equal the
shipped ones as structure exactly and as numbers within 1e-12: what another x86-64 (or an ARM)
machine computes differs from this one in the last bits only.

Not regenerated here: config/pump_boom_regions.yaml (pump_boom_regions takes about a minute);
its numbers are checked with a tolerance where the machine loads it (RegionTable.load).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from artefacts import bag_differences, xml_differences

from manipulator_kinematics.bag.synthetic import golden_name
from manipulator_kinematics.registry import machines

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parent.parent
DATA = REPO / "test" / "data"


def optional_features() -> list[str]:
    """numpy's dispatch targets this CPU supports (the baseline cannot be switched off)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    return [name for name in __cpu_dispatch__ if __cpu_features__.get(name)]


REGENERATE = """
import json, runpy, sys
from numpy._core._multiarray_umath import __cpu_features__
from manipulator_kinematics.urdf import main
out, features = sys.argv[1], sys.argv[2:]
assert main(["--all", out + "/urdf"]) == 0
sys.argv = ["make_golden_bags.py", "--output", out + "/data"]
try:
    runpy.run_path({script!r}, run_name="__main__")
except SystemExit as done:
    assert not done.code, done.code
print(json.dumps({{name: bool(__cpu_features__.get(name)) for name in features}}))
"""


@pytest.fixture(scope="module")
def regenerated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str], dict[str, bool]]:
    out = tmp_path_factory.mktemp("no_simd")
    features = optional_features()
    env = dict(os.environ, NPY_DISABLE_CPU_FEATURES=" ".join(features))
    code = REGENERATE.format(script=str(REPO / "scripts" / "make_golden_bags.py"))
    done = subprocess.run(
        [sys.executable, "-c", code, str(out), *features],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return out, features, json.loads(done.stdout.splitlines()[-1])


def test_the_subprocess_ran_without_the_optional_features(regenerated) -> None:
    _, features, seen = regenerated
    # Empty on a CPU with none of them (then the run is the baseline anyway).
    assert set(seen) == set(features) and not any(seen.values()), seen


def test_urdfs_without_simd_are_the_shipped_ones(regenerated) -> None:
    out, _, _ = regenerated
    names = sorted(p.name for p in (REPO / "urdf").glob("*.urdf"))
    fresh = sorted(p.name for p in (out / "urdf").iterdir())
    assert names == fresh == sorted(f"{m}.urdf" for m in machines())
    for name in names:
        differences = xml_differences((REPO / "urdf" / name).read_text(), (out / "urdf" / name).read_text())
        assert not differences, (name, differences[:5])


def test_golden_bags_without_simd_are_the_shipped_ones(regenerated) -> None:
    out, _, _ = regenerated
    bags = sorted(golden_name(m.name) for m in machines().values() if m.synthesize is not None)
    assert bags and bags == sorted(p.name for p in (out / "data").iterdir())
    for bag in bags:
        differences = bag_differences(DATA / bag, out / "data" / bag)
        assert not differences, (bag, differences[:5])
