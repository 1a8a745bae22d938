"""The layering rules of the package, checked on the source: the shared package imports no machine
package (machines are found through the registry), nothing uses rclpy's private internals, and the
excavator package's subpackages import downwards only, its core without ROS, with no import circle
and no module reading another's private names (docs/architecture.md, "The excavator package")."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

from manipulator_kinematics.registry import machines

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO / "manipulator_kinematics"
MACHINE_PACKAGES = sorted(p.parent.name for p in REPO.glob("*_kinematics/__init__.py") if p.parent != SHARED)


@functools.cache
def is_module(name: str) -> bool:
    path = REPO.joinpath(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def module_name(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(source: str, *, functions: bool = True, type_checking: bool = True) -> set[str]:
    """The modules a source imports (``from package import module`` counts as the module); without
    ``functions`` only what runs at import (nothing inside a function), without ``type_checking``
    nothing under ``if TYPE_CHECKING:`` (it never runs)."""
    tree = ast.parse(source)
    skipped: set[int] = set()
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.If)
            and ast.unparse(node.test).endswith("TYPE_CHECKING")
            and not type_checking
        ):
            skipped.update(id(inner) for statement in node.body for inner in ast.walk(statement))
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and not functions:
            skipped.update(id(inner) for inner in ast.walk(node))
    names = set()
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0 and node.module, f"relative import: {ast.unparse(node)}"
            for alias in node.names:
                inner = f"{node.module}.{alias.name}"
                names.add(inner if is_module(inner) else node.module)
    return names


def imported_modules(path: Path) -> set[str]:
    return imports(path.read_text(encoding="utf-8"))


def test_the_shared_package_imports_no_machine_package() -> None:
    assert {"excavator_kinematics", "scara_kinematics"} <= set(MACHINE_PACKAGES)
    offenders = {
        str(path.relative_to(REPO)): sorted(
            m for m in imported_modules(path) if m.split(".")[0] in MACHINE_PACKAGES
        )
        for path in SHARED.rglob("*.py")
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_no_rclpy_private_internals() -> None:
    private = ("rclpy.impl", "rclpy._rclpy_pybind11")
    offenders = {
        str(path.relative_to(REPO)): sorted(m for m in imported_modules(path) if m.startswith(private))
        for folder in [SHARED, *(REPO / m for m in MACHINE_PACKAGES)]
        for path in folder.rglob("*.py")
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_every_machine_package_is_registered_under_its_name() -> None:
    # The hydraulic family's machines are files: their records come from the shared layer.
    family = [m for m in machines().values() if m.section == "hydraulic_machine"]
    assert family and all(
        m.factory.__module__.startswith("manipulator_kinematics.hydraulic.") for m in family
    )
    registered = {m.factory.__module__.split(".")[0] for m in machines().values() if m not in family}
    assert registered == set(MACHINE_PACKAGES)
    for name, machine in machines().items():
        assert machine.name == name and machine.schema and machine.topics


# ---------------------------------------------------------------- the excavator package's layout
EXCAVATOR = REPO / "excavator_kinematics"
#: The excavator's subpackages by layer: a module imports its own subpackage and lower layers only;
#: the top-level ``machine`` (the registry record) imports ``core`` only (docs/architecture.md).
LAYERS = {"core": 0, "sensing": 1, "grade": 1, "nodes": 2, "tools": 3, "demo": 3}
#: Public names of the standard library that start with an underscore (namedtuple's methods).
PUBLIC_UNDERSCORED = {"_replace", "_asdict", "_fields", "_make", "_exit"}


def is_ros(module: str) -> bool:
    top = module.split(".")[0]
    return top in ("rclpy", "manipulator_kinematics_interfaces") or top.endswith("_msgs")


def layer(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 2 and parts[0] == "excavator_kinematics" else None


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every strongly connected component of more than one module, or a module importing itself
    (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for other in graph.get(node, ()):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                component.append(member)
                if member == node:
                    break
            if len(component) > 1 or node in graph.get(node, ()):
                cycles.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return cycles


def private_reads(source: str) -> list[str]:
    """``obj._name`` reads (and ``from m import _name``) of private names the source does not
    define itself (as a function, class, variable, argument or attribute it assigns)."""
    tree = ast.parse(source)
    own = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            own.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            own.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            own.add(node.attr)
        elif isinstance(node, ast.arg):
            own.add(node.arg)

    def private(name: str) -> bool:
        return name.startswith("_") and not name.startswith("__") and name not in own | PUBLIC_UNDERSCORED

    reads = [
        f"line {node.lineno}: {ast.unparse(node)}"
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute) and private(node.attr)
    ]
    reads += [
        f"line {node.lineno}: from {node.module} import {alias.name}"
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom)
        for alias in node.names
        if private(alias.name)
    ]
    return reads


def excavator_files() -> list[Path]:
    return sorted(EXCAVATOR.rglob("*.py"))


def test_the_checks_find_what_they_look_for() -> None:
    # Each helper on a case it must flag, so the tests below cannot pass by finding nothing.
    assert import_cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []
    source = (
        "from typing import TYPE_CHECKING\nimport rclpy\nif TYPE_CHECKING:\n    import std_msgs.msg\n"
        "def f():\n    import excavator_kinematics.nodes.sim_node\n"
    )
    assert imports(source) == {"typing", "rclpy", "std_msgs.msg", "excavator_kinematics.nodes.sim_node"}
    assert imports(source, functions=False, type_checking=False) == {"typing", "rclpy"}
    assert imports("from excavator_kinematics.core import inverse, machine_file") == {
        "excavator_kinematics.core.inverse",
        "excavator_kinematics.core.machine_file",
    }
    assert private_reads(
        "class A:\n    def f(self, m):\n        self._x = m._y\n        return self._x\n"
    ) == ["line 3: m._y"]
    assert private_reads("from a import _b\nt._replace(x=1)\n") == ["line 1: from a import _b"]


def test_the_excavator_subpackages_are_the_documented_layers() -> None:
    assert {p.parent.name for p in EXCAVATOR.glob("*/__init__.py")} == set(LAYERS)
    assert {p.name for p in EXCAVATOR.glob("*.py")} == {"__init__.py", "machine.py"}
    # docs/architecture.md draws the layout: every subpackage and every module of it
    architecture = (REPO / "docs" / "architecture.md").read_text(encoding="utf-8")
    drawn = architecture[architecture.index("## The excavator package") :]
    assert [f"{name}/" for name in LAYERS if f"{name}/" not in drawn] == []
    assert [p.name for p in excavator_files() if p.name not in drawn] == []


def test_the_excavator_core_and_kernels_import_no_ros_and_nothing_above_them() -> None:
    core = sorted((EXCAVATOR / "core").glob("*.py"))
    assert {"kinematics.py", "inverse.py", "state_kernel.py", "ik_kernel.py"} <= {p.name for p in core}
    offenders = {
        p.name: sorted(
            m
            for m in imports(p.read_text(encoding="utf-8"))
            if is_ros(m) or (m.startswith("excavator_kinematics") and layer(m) != "core")
        )
        for p in core
    }
    assert {k: v for k, v in offenders.items() if v} == {}
    # Nor does anything they load on import: the closure of import-time imports over our packages.
    seen, todo = set(), [module_name(p) for p in core]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        path = REPO.joinpath(*name.split("."))
        path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
        if path.is_file():
            todo += imports(path.read_text(encoding="utf-8"), functions=False, type_checking=False)
    assert "manipulator_kinematics.compiled" in seen and "numba" in seen
    assert sorted(m for m in seen if is_ros(m)) == []


def test_the_excavator_subpackages_import_downwards_only() -> None:
    offenders = []
    for path in excavator_files():
        here = module_name(path)
        for there in imports(path.read_text(encoding="utf-8")):
            if not there.startswith("excavator_kinematics"):
                continue
            own, other = layer(here), layer(there)
            if own is None:  # machine.py: core only; __init__.py: nothing of its own package
                allowed = here == "excavator_kinematics.machine" and other == "core"
            else:
                allowed = other is not None and (other == own or LAYERS[other] < LAYERS[own])
            if not allowed:
                offenders.append(f"{here} imports {there}")
    assert offenders == []


def test_no_import_circle_in_the_excavator_package() -> None:
    # Type-only imports (if TYPE_CHECKING:) run nothing and are left out; imports inside functions count.
    graph = {
        module_name(path): {
            m
            for m in imports(path.read_text(encoding="utf-8"), type_checking=False)
            if m.startswith("excavator_kinematics.")
        }
        for path in excavator_files()
    }
    assert len(graph) > 30
    assert import_cycles(graph) == []


def test_no_excavator_module_reads_another_modules_private_names() -> None:
    offenders = {
        str(path.relative_to(REPO)): reads
        for path in excavator_files()
        if (reads := private_reads(path.read_text(encoding="utf-8")))
    }
    assert offenders == {}
