#!/usr/bin/env bash
# The whole test suite: set up (or refresh) the venv, lint, format check, mypy, then pytest
# over test/. `--fast` (first argument) runs only the fast tier: -m "not ros and not slow"
# (no processes, no DDS, nothing over about 5 s; see CONTRIBUTING.md) on two workers (-n 2).
# Extra arguments go to pytest, e.g. `bash scripts/test.sh -k excavator -x`.
# Exit status: non-zero if set-up, ruff, mypy or any test fails (pytest's 5, "no tests ran",
# included). Every check runs even if another failed, so one run shows every problem.
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
tier=()
if [ "${1:-}" = "--fast" ]; then
    shift
    # In-process tests only: two workers (pytest-xdist) use both cores of the reference machine.
    tier=(-m "not ros and not slow" -n 2)
fi
bash "$REPO/scripts/bootstrap.sh"
# shellcheck source=scripts/env.sh
. "$REPO/scripts/env.sh"
cd "$REPO"
export MPLBACKEND=Agg

echo "[test] ruff check ."
ruff_status=0
ruff check . || ruff_status=$?
echo "[test] ruff format --check ."
format_status=0
ruff format --check . || format_status=$?
echo "[test] mypy (files: [tool.mypy] in pyproject.toml)"
mypy_status=0
mypy || mypy_status=$?

echo "[test] python -m pytest ${tier[*]} $* (testpaths: test/)"
# Backstop for a hang outside any one test (pytest-timeout covers each test; see pyproject.toml).
guard=()
if command -v timeout >/dev/null 2>&1; then
    guard=(timeout --foreground --kill-after=60 "${MK_TEST_TIMEOUT:-4800}")
fi
pytest_status=0
"${guard[@]}" python -m pytest ${tier[@]+"${tier[@]}"} "$@" </dev/null || pytest_status=$?
[ "$pytest_status" -ne 124 ] || echo "[test] pytest did not finish within ${MK_TEST_TIMEOUT:-4800} s" >&2

if [ "$ruff_status" -ne 0 ] || [ "$format_status" -ne 0 ] || [ "$mypy_status" -ne 0 ] \
    || [ "$pytest_status" -ne 0 ]; then
    echo "[test] FAILED: ruff exit $ruff_status, ruff format exit $format_status," \
        "mypy exit $mypy_status, pytest exit $pytest_status" >&2
    exit 1
fi
echo "[test] ruff, ruff format, mypy and pytest passed"
