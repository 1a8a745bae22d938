"""Docstrings as plain text for ``--help``: reST roles and literals without their markup.

``:meth:`Excavator.state``` -> ``Excavator.state``, ````joint_states```` -> ``joint_states``,
``:class:`~a.b.C``` -> ``C`` (the tilde keeps the last name, as Sphinx shows it).
"""

from __future__ import annotations

import re

_ROLE = re.compile(r":[a-z]+(?::[a-z]+)?:`(~?)([^`<]*?)(?:\s*<[^>]*>)?`")
_LITERAL = re.compile(r"``(.+?)``", re.S)


def plain(text: str) -> str:
    """``text`` (reST from a docstring) with roles and inline literals reduced to their words."""

    def role(match: re.Match[str]) -> str:
        name = match[2].strip()
        return name.rsplit(".", 1)[-1] if match[1] else name

    return _LITERAL.sub(r"\1", _ROLE.sub(role, text))


__all__ = ["plain"]
