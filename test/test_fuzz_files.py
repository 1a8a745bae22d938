"""Fuzz of every file input (issue 29): parameters and machine YAML, pump boom region tables,
LandXML design surfaces, bag metadata.

Seeds are issue 29's reproductions (a 1.4 KB nine-level alias bomb, a FIFO, /dev/zero, a
directory, deep nesting, tabs, non-UTF-8, ``!!python`` tags, duplicate and overlapping faces,
1e300 coordinates, ...), then mutations of the shipped files (fixed seed, a fixed count). Every
input is read or refused with the reader's own error in one line naming the file, each within
READ_LIMIT seconds, no other exception and no warning. The command-line tests run the console
scripts on the seeds: exit 2, one line on stderr, no traceback.
"""

from __future__ import annotations

import os
import shutil
import time
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from excavator_kinematics.grade.design_surface import MAX_ELEMENTS, read_landxml
from manipulator_kinematics.bag.evaluate import load_setup
from manipulator_kinematics.bag.reader import MAX_BAG_BYTES, BagReader
from manipulator_kinematics.bag.types import BagError
from manipulator_kinematics.param_files import MAX_DEPTH, ConfigError, check_ros_arguments, config_path
from manipulator_kinematics.registry import machine
from pump_boom_kinematics import build_regions
from pump_boom_kinematics.kinematics import PumpBoom
from pump_boom_kinematics.regions import RegionTable

HERE = Path(__file__).resolve().parent
#: Most CPU time one read or refusal may take (s): the alias bomb took 30 s and more, unrefused.
#: CPU time of this process, not wall time: on a loaded machine (CI, two test workers) a read of
#: 2 s CPU took 10.8 s wall.
READ_LIMIT = 5.0
MUTATIONS = 60
#: Tokens spliced into the shipped files by the mutations.
TOKENS = [
    b"&a ",
    b"*a",
    b"!!python/object/apply:os.system ['true'] ",
    b"\t",
    b"\xff\xfe",
    b"[" * 40,
    b"{",
    b": ",
    b"\x00",
    b"1e999",
    b"- ",
    b"? ",
    b"!!binary aGk= ",
    b"2001-13-45",
    b"9" * 5000,
    b"---\n",
    b"'",
    b'"',
    b"\n  ",
    b"<<: {a: 1}",
    b"nan",
    b"-.inf",
    b"~",
    b"!x ",
]


def alias_bomb() -> bytes:
    """Nine levels of ``&bN {k0: *bN-1, ...}`` (1.4 KB): 9^9 leaves once expanded."""
    lines = ["b0: &b0 {k0: x, k1: x, k2: x, k3: x, k4: x, k5: x, k6: x, k7: x, k8: x}"]
    for n in range(1, 10):
        lines.append(f"b{n}: &b{n} {{" + ", ".join(f"k{i}: *b{n - 1}" for i in range(9)) + "}")
    return ("\n".join(lines) + "\n").encode()


def in_params(body: bytes) -> bytes:
    return b"/**:\n  ros__parameters:\n    scara:\n      l1: " + body + b"\n"


#: name -> bytes of a file, or a callable making the path (special files) in a directory.
YAML_SEEDS: dict[str, bytes | Callable[[Path], Path]] = {
    "alias_bomb": alias_bomb(),
    "alias_in_params": in_params(b"&a [1.0, 2.0]\n      l2: *a"),
    "python_tag": in_params(b"!!python/object/apply:os.system ['true']"),
    "deep_nesting": b"a: " + b"[" * 100_000 + b"]" * 100_000 + b"\n",
    "deep_mapping": b"".join(b"  " * i + b"k:\n" for i in range(MAX_DEPTH + 5)) + b" " * 80 + b"1\n",
    "tabs": b"/**:\n\tros__parameters:\n\t\tscara: {l1: 1.0}\n",
    "not_utf8": in_params(b"'\xff\xfe'"),
    "utf16": "/**:\n  ros__parameters: {x: 1}\n".encode("utf-16"),
    "long_list": in_params(b"[" + b"0.1, " * 20_000 + b"0.1]"),
    "wide_mapping": b"{" + b", ".join(b"k%d: 1" % i for i in range(20_000)) + b"}\n",
    "huge_int": in_params(b"9" * 5000),
    "bad_date": in_params(b"2001-13-45"),
    "two_documents": b"a: 1\n---\nb: 2\n",
    "nul": b"a: \x00\n",
    "empty": b"",
    "garbage": bytes(range(256)),
    "fifo": lambda d: (os.mkfifo(d / "fifo.yaml"), d / "fifo.yaml")[1],
    "dev_zero": lambda d: Path("/dev/zero"),
    "directory": lambda d: (d / "dir.yaml").mkdir() or d / "dir.yaml",
    "missing": lambda d: d / "missing.yaml",
    "over_4_mib": lambda d: sparse(d / "big.yaml", 5 << 20),
}


def sparse(path: Path, size: int) -> Path:
    with path.open("wb") as stream:
        stream.truncate(size)
    return path


def mutations(text: bytes, count: int, seed: int) -> Iterator[bytes]:
    """``count`` damaged copies of ``text``: bytes changed, cut, tokens spliced in, lines doubled
    or dropped (a fixed seed: the same cases every run)."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        data = bytearray(text)
        for _ in range(int(rng.integers(1, 4))):
            kind, at = int(rng.integers(5)), int(rng.integers(len(data) + 1))
            if kind == 0 and data:
                data[min(at, len(data) - 1)] = int(rng.integers(256))
            elif kind == 1:
                del data[at:]
            elif kind == 2:
                data[at:at] = TOKENS[int(rng.integers(len(TOKENS)))]
            else:
                lines = bytes(data).split(b"\n")
                k = int(rng.integers(len(lines)))
                lines[k : k + 1] = [lines[k]] * 2 if kind == 3 else []
                data = bytearray(b"\n".join(lines))
        yield bytes(data)


def cases(
    seeds: dict[str, bytes | Callable[[Path], Path]], shipped: bytes, directory: Path, seed: int
) -> Iterator[tuple[str, Path]]:
    for name, seed_input in seeds.items():
        if callable(seed_input):
            yield name, seed_input(directory)
        else:
            path = directory / f"{name}.in"
            path.write_bytes(seed_input)
            yield name, path
    for k, data in enumerate(mutations(shipped, MUTATIONS, seed)):
        path = directory / f"mutation_{k}.in"
        path.write_bytes(data)
        yield f"mutation {k}", path


def read_or_refuse(
    name: str, path: Path, read: Callable[[], object], errors: tuple[type, ...], names_file: bool = True
) -> str | None:
    """Run ``read``: it returns, or raises one of ``errors`` with one line (naming the file unless
    not ``names_file``: a machine's validation names the key), within READ_LIMIT, warning nothing;
    the line (None if it read)."""
    start = time.process_time()
    line = None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            read()
        except errors as error:
            line = str(error)
    took = time.process_time() - start
    assert took < READ_LIMIT, (name, took)
    if line is not None:
        assert "\n" not in line and len(line) < 400, (name, line[:500])
        assert not names_file or str(path) in line, (name, line)
    return line


def test_yaml_seeds_are_refused_by_their_reason(tmp_path: Path) -> None:
    reasons = {
        "alias_bomb": "anchor &b0: anchors are refused",
        "alias_in_params": "/**: scara.l1 (line 4): anchor &a",
        "python_tag": "tag 'tag:yaml.org,2002:python/object/apply:os.system'",
        "deep_nesting": f"nested deeper than the {MAX_DEPTH} levels",
        "deep_mapping": f"nested deeper than the {MAX_DEPTH} levels",
        "tabs": "not valid YAML (line 2)",
        "not_utf8": "not UTF-8 text (byte 46)",
        "utf16": "not UTF-8 text (byte 0)",
        "long_list": "/**: scara.l1 (line 4): more than the 10000 items",
        "wide_mapping": "line 1: more than the 10000 items",
        "huge_int": "a value cannot be read",
        "bad_date": "a value cannot be read: month must be in 1..12",
        "two_documents": "not valid YAML (line 2)",
        "nul": "not valid YAML",
        "garbage": "not UTF-8 text",
        "fifo": "a FIFO, not a regular file",
        "dev_zero": "a character device, not a regular file",
        "directory": "a directory, not a regular file",
        "missing": "No such file or directory",
        "over_4_mib": "5.0 MiB, more than the 4 MiB",
    }
    for name, path in cases(YAML_SEEDS, b"", tmp_path, 0):
        if name in reasons:
            line = read_or_refuse(
                name,
                path,
                lambda p=path: check_ros_arguments(["exe", "--ros-args", "--params-file", str(p)]),
                (ConfigError,),
            )
            assert line is not None and reasons[name] in line, (name, line)


@pytest.mark.parametrize("name", ["scara", "excavator", "pump_boom"])
def test_fuzzed_params_and_machine_files_are_read_or_refused_in_one_line(tmp_path: Path, name: str) -> None:
    """What check_ros_arguments (every node), Machine.parameters (mk_urdf, the cores) and
    mk_evaluate's load_setup do with each file."""
    kind = machine(name)
    shipped = config_path(kind.config_file).read_bytes()
    for case, path in cases(YAML_SEEDS, shipped, tmp_path, hash(name) % 1000):
        read_or_refuse(
            case,
            path,
            lambda p=path: check_ros_arguments(["exe", "--ros-args", "--params-file", str(p)]),
            (ConfigError,),
        )
        read_or_refuse(case, path, lambda p=path: kind.model(p), (ConfigError,), names_file=False)
        read_or_refuse(case, path, lambda p=path: load_setup([p]), (BagError,), names_file=False)


def test_fuzzed_region_tables_are_read_or_refused_in_one_line(tmp_path: Path, capsys) -> None:
    """RegionTable.load (pump_boom_ik_server, region IK) and pump_boom_regions --list."""
    boom = PumpBoom.default()
    shipped = config_path("pump_boom_regions.yaml").read_bytes()
    lines = 0
    for case, path in cases(YAML_SEEDS, shipped, tmp_path, 29):
        if read_or_refuse(
            case, path, lambda p=path: RegionTable.load(p, boom.table_key()), (ConfigError,), names_file=False
        ):
            lines += 1
            code = build_regions.main(["--list", "--output", str(path)])
            err = capsys.readouterr().err
            assert code == 2 and err.count("\n") == 1, (case, code, err)
    assert lines >= len(YAML_SEEDS)


def landxml(
    points: list[tuple[float, float, float]], faces: list[tuple[int, int, int]], head: str = ""
) -> str:
    """A LandXML TIN (x, y, z points; 1-based faces), written by hand: Tin refuses these."""
    p = "".join(f'<P id="{i + 1}">{y} {x} {z}</P>' for i, (x, y, z) in enumerate(points))
    f = "".join(f"<F>{a} {b} {c}</F>" for a, b, c in faces)
    return (
        f'<?xml version="1.0"?>{head}<LandXML xmlns="http://www.landxml.org/schema/LandXML-1.2">'
        f'<Surfaces><Surface name="Ditch design"><Definition surfType="TIN"><Pnts>{p}</Pnts>'
        f"<Faces>{f}</Faces></Definition></Surface></Surfaces></LandXML>"
    )


SQUARE = [(0.0, 0.0, 0.0), (10.0, 0.0, 0.0), (10.0, 10.0, 0.0), (0.0, 10.0, 0.0)]
LAUGHS = (
    '<!DOCTYPE l [<!ENTITY b0 "aaaaaaaaaa">'
    + "".join(f'<!ENTITY b{i} "{f"&b{i - 1};" * 10}">' for i in range(1, 10))
    + "]>"
)
LANDXML_SEEDS: dict[str, bytes | Callable[[Path], Path]] = {
    "duplicate_face": landxml(SQUARE, [(1, 2, 3), (1, 3, 4), (1, 2, 3)]).encode(),
    "reversed_duplicate": landxml(SQUARE, [(1, 2, 3), (1, 3, 4), (3, 2, 1)]).encode(),
    "fold": landxml([*SQUARE, (5.0, 2.0, 0.0)], [(1, 2, 3), (1, 3, 4), (1, 2, 5)]).encode(),
    "crossing": landxml(
        [(0, 0, 0), (10, 0, 0), (5, 9, 0), (0, 6, 1), (10, 6, 1), (5, -3, 1)], [(1, 2, 3), (4, 5, 6)]
    ).encode(),
    "face_inside_a_face": landxml(
        [*SQUARE, (2.0, 3.0, 0.0), (4.0, 3.0, 0.0), (3.0, 5.0, 0.0)], [(1, 2, 3), (1, 3, 4), (5, 6, 7)]
    ).encode(),
    "coordinates_1e300": landxml([(0, 0, 0), (1e300, 0, 0), (0, 1e300, 0)], [(1, 2, 3)]).encode(),
    "elevation_1e300": landxml([(0, 0, 0), (1, 0, 1e300), (0, 1, 0)], [(1, 2, 3)]).encode(),
    "billion_laughs": landxml(SQUARE, [(1, 2, 3)], LAUGHS).replace('"Ditch design"', '"&b9;"').encode(),
    "external_entity": landxml(SQUARE, [(1, 2, 3)], '<!DOCTYPE l [<!ENTITY x SYSTEM "file:///etc/passwd">]>')
    .replace('"Ditch design"', '"&x;"')
    .encode(),
    "too_many_elements": (
        '<LandXML><Surfaces><Surface name="Ditch design"><Definition surfType="TIN"><Faces>'
        + "<F>1 2 3</F>" * (MAX_ELEMENTS + 1)
    ).encode(),
    "not_xml": b"/**:\n  ros__parameters: {}\n",
    "fifo": lambda d: (os.mkfifo(d / "fifo.xml"), d / "fifo.xml")[1],
    "dev_zero": lambda d: Path("/dev/zero"),
    "directory": lambda d: (d / "dir.xml").mkdir() or d / "dir.xml",
    "over_32_mib": lambda d: sparse(d / "big.xml", 33 << 20),
}


def test_fuzzed_design_surfaces_are_read_or_refused_in_one_line(tmp_path: Path) -> None:
    reasons = {
        "duplicate_face": "faces 0 and 2 lie on the same side of their edge",
        "reversed_duplicate": "faces 0 and 2 lie on the same side",
        "fold": "faces 0 and 2 lie on the same side",
        "crossing": "faces overlap in plan view (edges of two faces cross)",
        "face_inside_a_face": "vertex 4 lies inside face 1",
        "coordinates_1e300": "vertex 1 at [1e+300, 0.0, 0.0] m is no place on a site",
        "elevation_1e300": "vertex 1 at [1.0, 0.0, 1e+300] m is no place on a site",
        "billion_laughs": "cannot read a LandXML file",
        "external_entity": "reference to external entity",
        "too_many_elements": f"more than the {MAX_ELEMENTS} XML elements",
        "not_xml": "cannot read a LandXML file",
        "fifo": "a FIFO, not a regular file",
        "dev_zero": "a character device, not a regular file",
        "directory": "a directory, not a regular file",
        "over_32_mib": "33.0 MiB, more than the 32 MiB",
    }
    shipped = (HERE / "data" / "landxml" / "ditch.xml").read_bytes()
    for case, path in cases(LANDXML_SEEDS, shipped, tmp_path, 5):
        line = read_or_refuse(case, path, lambda p=path: read_landxml(p, "Ditch design"), (ConfigError,))
        if case in reasons:
            assert line is not None and reasons[case] in line, (case, line)


def test_fuzzed_bag_metadata_is_read_or_refused_in_one_line(tmp_path: Path) -> None:
    golden = HERE / "data" / "scara_forward_golden"
    shipped = (golden / "metadata.yaml").read_bytes()
    bag = tmp_path / "bag"
    shutil.copytree(golden, bag)
    meta = bag / "metadata.yaml"
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    refused = 0
    for case, path in cases({k: v for k, v in YAML_SEEDS.items() if not callable(v)}, shipped, inputs, 3):
        shutil.copyfile(path, meta)
        refused += read_or_refuse(case, meta, lambda: BagReader(bag), (BagError,)) is not None
    assert refused >= len(YAML_SEEDS) - 5


def test_a_bag_larger_than_its_bound_is_refused_before_it_is_read(tmp_path: Path) -> None:
    path = tmp_path / "big.mcap"
    with path.open("wb") as stream:  # sparse: the size without the disk space
        stream.write(b"\x89MCAP0\r\n")
        stream.truncate(MAX_BAG_BYTES + 1)
    line = read_or_refuse("big bag", path, lambda: BagReader(path), (BagError,))
    assert line is not None and "2.0 GiB of data files, more than the 2 GiB" in line, line
