"""The repository stands alone: no file outside test/ (code, README, docs, config, scripts, ...)
points at the team's notes and papers beside the checkout (``../shared``, ``shared/reference``,
``shared/seeds``, ``/work/shared``), which users of the repository do not have. What users need
from them is in docs/ (issue 9, item 8)."""

from __future__ import annotations

from pathlib import Path

OUTSIDE = ("../shared", "shared/reference", "shared/seeds", "/work/shared")


def pointers(path: Path) -> list[str]:
    """``file:line: text`` of each line of ``path`` that names a place outside the repository."""
    text = path.read_bytes().decode("utf-8", errors="replace")
    return [
        f"{path.name}:{number}: {line.strip()}"
        for number, line in enumerate(text.splitlines(), 1)
        if any(pattern in line for pattern in OUTSIDE)
    ]


def test_the_check_finds_each_form_of_pointer(tmp_path: Path) -> None:
    lines = [
        "see ../shared/reference/platform.md",
        "(/work/shared/seeds/000.pdf)",
        "shared/reference/x.md",
        "the shared package, manipulator_kinematics/",
        "shared/ alone",
    ]
    (tmp_path / "note.md").write_text("\n".join(lines))
    assert [hit.split(":")[1] for hit in pointers(tmp_path / "note.md")] == ["1", "2", "3"]
