"""The repository stands alone: no file outside test/ (code, README, docs, config, scripts, ...)
points at the team's notes and papers beside the checkout (``../shared``, ``shared/reference``,
``shared/seeds``, ``/work/shared``), which users of the repository do not have. What users need
from them is in docs/ (issue 9, item 8)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
OUTSIDE = ("../shared", "shared/reference", "shared/seeds", "/work/shared")


def repository_files() -> list[Path]:
    """Every file git tracks or would add (not ignored), outside test/ (whose own files may name
    the patterns, as this one does)."""
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("not a git checkout")
    listed = (
        subprocess.run(
            ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
            cwd=REPO,
            capture_output=True,
            check=True,
            timeout=60,
        )
        .stdout.decode()
        .split("\0")
    )
    paths = [REPO / name for name in listed if name and not name.startswith("test/")]
    return [path for path in paths if path.is_file()]


def pointers(path: Path) -> list[str]:
    """``file:line: text`` of each line of ``path`` that names a place outside the repository."""
    text = path.read_bytes().decode("utf-8", errors="replace")
    return [
        f"{path.name}:{number}: {line.strip()}"
        for number, line in enumerate(text.splitlines(), 1)
        if any(pattern in line for pattern in OUTSIDE)
    ]


@pytest.mark.ros
def test_nothing_points_outside_the_repository() -> None:
    files = repository_files()
    assert REPO / "README.md" in files and REPO / "docs" / "bags.md" in files and REPO / "setup.py" in files
    found = [hit for path in files for hit in pointers(path)]
    assert not found, "files point outside the repository:\n" + "\n".join(found)


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
