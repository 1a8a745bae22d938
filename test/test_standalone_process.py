"""The repository's tracked files (ros tier: git runs as a child process) point nowhere outside it;
the rule itself is in test_standalone.py."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
from test_standalone import pointers

pytestmark = pytest.mark.ros


REPO = Path(__file__).resolve().parent.parent


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


def test_nothing_points_outside_the_repository() -> None:
    files = repository_files()
    assert REPO / "README.md" in files and REPO / "docs" / "bags.md" in files and REPO / "setup.py" in files
    found = [hit for path in files for hit in pointers(path)]
    assert not found, "files point outside the repository:\n" + "\n".join(found)
