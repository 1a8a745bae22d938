"""One validation for every machine description and node setting (numpy cores, nodes, ``evaluate``).

A schema is a nested mapping ``{key: Field or schema}``. :func:`validate` walks a nested parameter
dict against it and returns the values converted to plain Python (floats, ints, lists, strings);
anything else raises :class:`ConfigError` naming the dotted key:

* a key the schema does not know (with "did you mean ..." for a near miss: ``boom.lenght``);
* a key the schema requires that is missing (every field is required unless it has a default);
* a value of the wrong type (``true`` for a number, a string inside a point list), not finite,
  outside its range, or a list of the wrong length.

Consistency between keys (a reference angle inside its limits, lower below upper) is checked by
the model that reads them, with :func:`require`, so the message still names the key.

Each field's ``doc`` becomes the description of the ROS parameter a node declares for it, and its
``describe()`` (what it takes: kind, range, unit) the parameter's constraints.

Ranges are sanity bounds, not the machine's limits: ``Number(min=0, max=100, unit="m")`` refuses a
link length of 1e300 m that no machine of this package can have.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Union

from manipulator_kinematics.param_files import SHOWN, ConfigError, shown

__all__ = [
    "ConfigError",
    "Flag",
    "Names",
    "Number",
    "Numbers",
    "Schema",
    "Text",
    "Tree",
    "defaults",
    "require",
    "validate",
]

#: Marks a field without a default: the key must be given.
REQUIRED: Any = object()


@dataclass(frozen=True)
class Number:
    """A finite real number in [min, max] (``integer`` for whole numbers); ``open``: -inf and inf
    are taken too (an open limit: YAML ``.inf``, ``-.inf``)."""

    min: float = -math.inf
    max: float = math.inf
    unit: str = ""
    integer: bool = False
    default: Any = REQUIRED
    exclusive_min: bool = False
    doc: str = ""
    open: bool = False

    def check(self, value: Any, key: str) -> float | int:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{key}: expected a number{_unit(self.unit)}, got {shown(value)}")
        if self.open and math.isinf(value):
            return float(value)
        if not math.isfinite(value):
            what = "a finite number or -.inf/.inf (open)" if self.open else "a finite number"
            raise ConfigError(f"{key}: expected {what}, got {shown(value)}")
        if self.integer and float(value) != int(value):
            raise ConfigError(f"{key}: expected a whole number, got {shown(value)}")
        below = value <= self.min if self.exclusive_min else value < self.min
        if below or value > self.max:
            low = "(" if self.exclusive_min else "["
            interval = f"{low}{self.min:g}, {self.max:g}]"
            raise ConfigError(f"{key} = {shown(value)} is outside {interval}{_unit(self.unit)}")
        return int(value) if self.integer else float(value)

    def describe(self) -> str:
        """What the field takes, for ``ros2 param describe`` and ``--help``: kind, range and unit."""
        low = "(" if self.exclusive_min else "["
        kind = f"{'whole ' if self.integer else ''}number in {low}{self.min:g}, {self.max:g}]"
        return kind + (f" {self.unit}" if self.unit else "") + (", or -inf/inf (open)" if self.open else "")


@dataclass(frozen=True)
class Numbers:
    """A list of ``count`` numbers (any length when count is None), each checked as ``item``."""

    count: int | None = None
    item: Number = Number()
    default: Any = REQUIRED
    doc: str = ""

    def check(self, value: Any, key: str) -> list[float | int]:
        if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Sequence):
            raise ConfigError(f"{key}: expected a list of {self._what()}, got {shown(value)}")
        if self.count is not None and len(value) != self.count:
            raise ConfigError(f"{key}: expected {self._what()}, got {len(value)}: {shown(value)}")
        return [self.item.check(v, f"{key}[{i}]") for i, v in enumerate(value)]

    def _what(self) -> str:
        return f"{self.count} numbers" if self.count is not None else "numbers"

    def describe(self) -> str:
        count = "" if self.count is None else f"{self.count} "
        return f"list of {count}numbers, each a {self.item.describe()}"


@dataclass(frozen=True)
class Names:
    """A list of ``count`` distinct non-empty strings (joint names)."""

    count: int | None = None
    default: Any = REQUIRED
    doc: str = ""

    def check(self, value: Any, key: str) -> list[str]:
        if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Sequence):
            raise ConfigError(f"{key}: expected a list of names, got {shown(value)}")
        if self.count is not None and len(value) != self.count:
            raise ConfigError(f"{key}: expected {self.count} names, got {len(value)}: {shown(value)}")
        if not all(isinstance(v, str) and v for v in value) or len(set(value)) != len(value):
            raise ConfigError(f"{key}: names must be distinct non-empty strings, got {shown(value)}")
        return list(value)

    def describe(self) -> str:
        return f"list of {'' if self.count is None else f'{self.count} '}distinct names"


@dataclass(frozen=True)
class Text:
    """A string; ``choices`` restricts it, ``empty`` allows ''."""

    choices: tuple[str, ...] | None = None
    empty: bool = True
    default: Any = REQUIRED
    doc: str = ""

    def check(self, value: Any, key: str) -> str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {shown(value)}")
        if self.choices is not None and value not in self.choices:
            raise ConfigError(f"{key} = {shown(value)}: expected one of {', '.join(map(repr, self.choices))}")
        if not self.empty and not value:
            raise ConfigError(f"{key}: must not be empty")
        return value

    def describe(self) -> str:
        if self.choices:
            return "one of " + ", ".join(self.choices)
        return "text" if self.empty else "text, not empty"


@dataclass(frozen=True)
class Flag:
    """true or false (not 0/1, not a string)."""

    default: Any = REQUIRED
    doc: str = ""

    def check(self, value: Any, key: str) -> bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: expected true or false, got {shown(value)}")
        return value

    def describe(self) -> str:
        return "true or false"


@dataclass(frozen=True)
class Tree:
    """A nested mapping taken as it is (plain Python values), checked by the model that reads it:
    the parts of a hydraulic-family machine file whose keys are names the user chooses (bodies,
    pins, cylinders, dyads), which no fixed schema can list (its parser names the key)."""

    default: Any = REQUIRED
    doc: str = ""

    def check(self, value: Any, key: str) -> dict[str, Any] | None:
        if value is None and self.default is None:  # an optional part left out
            return None
        if not isinstance(value, Mapping) or not value:
            raise ConfigError(f"{key}: expected a mapping of names, got {shown(value)}")
        return _tree(value)

    def describe(self) -> str:
        return "mapping of names (checked by the machine's parser)"


Field = Number | Numbers | Names | Text | Flag | Tree
Schema = Mapping[str, Union[Field, "Schema"]]


def validate(values: Any, schema: Schema, prefix: str = "") -> dict[str, Any]:
    """``values`` checked against ``schema``: plain Python values, defaults filled in.

    Raises ConfigError naming the first unknown, missing or invalid key (dotted, under ``prefix``).
    """
    if not isinstance(values, Mapping):
        raise ConfigError(f"{prefix or 'parameters'}: expected a mapping of keys, got {shown(values)}")
    for key in values:
        if key not in schema:
            name = _join(prefix, key) if len(str(key)) <= SHOWN else _join(prefix, shown(str(key)))
            raise ConfigError(f"{name}: unknown key{_did_you_mean(str(key), schema)}")
    out: dict[str, Any] = {}
    for key, spec in schema.items():
        name = _join(prefix, key)
        if isinstance(spec, Mapping):
            if key not in values:
                if _all_defaulted(spec):
                    out[key] = validate({}, spec, name)
                    continue
                raise ConfigError(f"{name}: missing (a section with keys {', '.join(spec)})")
            out[key] = validate(values[key], spec, name)
        elif key in values:
            out[key] = spec.check(values[key], name)
        elif spec.default is REQUIRED:
            raise ConfigError(f"{name}: missing")
        else:
            out[key] = spec.default
    return out


def require(condition: bool, key: str, message: str) -> None:
    """Raise ConfigError ``"<key>: <message>"`` unless ``condition`` (a consistency check)."""
    if not condition:
        raise ConfigError(f"{key}: {message}")


def defaults(schema: Schema) -> dict[str, Any]:
    """The nested defaults of a schema whose every field has one."""
    return validate({}, schema)


def _all_defaulted(schema: Schema) -> bool:
    return all(
        _all_defaulted(s) if isinstance(s, Mapping) else s.default is not REQUIRED for s in schema.values()
    )


def _tree(value: Any) -> Any:
    """Nested mappings as plain dicts with string keys (lists and scalars as they are)."""
    if isinstance(value, Mapping):
        return {str(k): _tree(v) for k, v in value.items()}
    return list(value) if isinstance(value, (list, tuple)) else value


def _join(prefix: str, key: Any) -> str:
    return f"{prefix}.{key}" if prefix else str(key)


def _unit(unit: str) -> str:
    return f" ({unit})" if unit else ""


def _did_you_mean(key: str, schema: Schema) -> str:
    close = difflib.get_close_matches(key, [str(k) for k in schema], n=1, cutoff=0.6)
    known = ", ".join(map(str, schema))
    return f" (did you mean {close[0]!r}?)" if close else f" (known: {known})"
