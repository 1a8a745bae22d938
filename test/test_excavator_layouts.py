"""The packed constants of the excavator's kernels (excavator_kinematics.core.layouts): each layout
declared once, the packers filling every field by name with the value the numpy path reads, the
kernels reading no offset of their own, and a kernel compiled for another layout refused."""

from __future__ import annotations

import ast
import types
from pathlib import Path

import numpy as np
import pytest

from excavator_kinematics.core import ik_kernel, state_kernel
from excavator_kinematics.core.inverse import LIMIT_TOL, Constants
from excavator_kinematics.core.kinematics import Excavator
from excavator_kinematics.core.layouts import (
    FOUR_BAR,
    IK,
    STATE,
    TRIANGLE,
    FourBarConstants,
    Layout,
    TriangleConstants,
    check_compiled,
)
from excavator_kinematics.core.machine_file import STROKE_TOLERANCE

CORE = Path(state_kernel.__file__).parent
EXC = Excavator.default()


def test_the_state_constants_hold_each_field_where_the_layout_says() -> None:
    packed, at, g = EXC.packed, STATE.at, EXC.linkages
    assert packed.shape == (STATE.size,) == (5 + 3 * 7 + 2 + 8 + 4 + 4,)
    assert packed[[at.l0, at.l1, at.l2, at.l3, at.l4]].tolist() == [EXC.l0, EXC.l1, EXC.l2, EXC.l3, EXC.l4]
    for name, triangle in (("boom", g.boom), ("arm", g.arm), ("side", g.side)):
        start = getattr(at, name)
        for field in TriangleConstants._fields:
            assert packed[start + getattr(TRIANGLE.at, field)] == getattr(triangle.constants, field)
        # eq. 1 folded, against the triangle's own sides
        assert packed[start + TRIANGLE.at.c0] == pytest.approx(
            (triangle.a**2 + triangle.b**2) / (2 * triangle.a * triangle.b)
        )
    for field in FourBarConstants._fields:
        assert packed[at.four_bar + getattr(FOUR_BAR.at, field)] == getattr(g.h_constants, field)
    assert packed[at.four_bar + FOUR_BAR.at.b] == pytest.approx(np.hypot(*g.h_pin))
    np.testing.assert_array_equal(
        packed[at.pivot_from_bucket_pin : at.pivot_from_bucket_pin + 2], g.pivot - g.bucket_pin
    )
    np.testing.assert_array_equal(packed[at.lower : at.lower + 4], EXC.joint_limits.lower - STROKE_TOLERANCE)
    np.testing.assert_array_equal(packed[at.upper : at.upper + 4], EXC.joint_limits.upper + STROKE_TOLERANCE)


def test_the_ik_constants_hold_each_field_where_the_layout_says() -> None:
    k, at = EXC.ik_constants, IK.at
    assert k.packed.shape == (IK.size,)
    scalars = [field for field, size in IK.sizes.items() if size == 1]
    assert len(scalars) == 30 and set(scalars) <= set(Constants._fields)
    for field in scalars:
        assert k.packed[getattr(at, field)] == getattr(k, field)
    assert k.packed[at.l4] == EXC.l4 and k.packed[at.stroke_hi] == EXC.limits.stroke_max[2] + STROKE_TOLERANCE
    np.testing.assert_array_equal(k.packed[at.lower : at.lower + 4], EXC.joint_limits.lower - LIMIT_TOL)
    np.testing.assert_array_equal(k.packed[at.upper : at.upper + 4], EXC.joint_limits.upper + LIMIT_TOL)
    np.testing.assert_array_equal(k.packed[at.weights : at.weights + 4], k.weights)
    np.testing.assert_array_equal(k.packed[at.stroke_min : at.stroke_min + 3], EXC.limits.stroke_min)
    np.testing.assert_array_equal(k.packed[at.stroke_max : at.stroke_max + 3], EXC.limits.stroke_max)


@pytest.mark.parametrize("kernel", [state_kernel, ik_kernel], ids=lambda m: m.__name__.rsplit(".", 1)[1])
def test_a_kernel_reads_no_offset_of_its_own(kernel: types.ModuleType) -> None:
    # Every index into the packed constants k starts from a layout's offset (k[_K.arm + _T.c0],
    # k[_K.lower : _K.lower + 4]), never from a number typed here (k[5], k[30:34]).
    tree = ast.parse(Path(kernel.__file__).read_text(encoding="utf-8"))
    reads = [
        n for n in ast.walk(tree) if isinstance(n, ast.Subscript) and getattr(n.value, "id", None) == "k"
    ]

    def literal(index: ast.expr | None) -> bool:
        return isinstance(index, ast.Constant | ast.UnaryOp)

    typed = [
        ast.unparse(node)
        for node in reads
        if literal(node.slice)
        or (isinstance(node.slice, ast.Slice) and (literal(node.slice.lower) or literal(node.slice.upper)))
    ]
    assert typed == [] and len(reads) >= 10


def test_a_kernel_compiled_for_another_layout_is_refused() -> None:
    def compiled_with(signature: int) -> types.SimpleNamespace:
        return types.SimpleNamespace(__name__="k", LAYOUT_SIGNATURE=7, layout_signature=lambda: signature)

    check_compiled(compiled_with(7))
    with pytest.raises(RuntimeError, match="another packed layout"):
        check_compiled(compiled_with(8))
    # The signature follows every name, order and size.
    signatures = {
        Layout("L", sizes).signature
        for sizes in ({"a": 1, "b": 2}, {"b": 2, "a": 1}, {"a": 1, "b": 3}, {"a": 1, "c": 2})
    }
    assert len(signatures) == 4


def test_pack_refuses_a_missing_unknown_or_misshapen_field() -> None:
    layout = Layout("L", {"a": 1, "b": 2})
    np.testing.assert_array_equal(layout.pack({"b": [2.0, 3.0], "a": 1.0}), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match=r"missing \['b'\], unknown \['c'\]"):
        layout.pack({"a": 1.0, "c": 2.0})
    with pytest.raises(ValueError, match=r"L\.b: 3 values, the layout has 2"):
        layout.pack({"a": 1.0, "b": [1.0, 2.0, 3.0]})
