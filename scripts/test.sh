#!/usr/bin/env bash
# The whole test suite: set up (or refresh) the venv, lint, then pytest over test/.
# Extra arguments go to pytest, e.g. `bash scripts/test.sh -k excavator -x`.
# Exit status: non-zero if set-up, ruff or any test fails (pytest's 5, "no tests ran", included).
# ruff and pytest both run even if the other failed, so one run shows every problem.
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$REPO/scripts/bootstrap.sh"
# shellcheck source=scripts/env.sh
. "$REPO/scripts/env.sh"
cd "$REPO"
export MPLBACKEND=Agg

echo "[test] ruff check ."
ruff_status=0
ruff check . || ruff_status=$?

echo "[test] python -m pytest $* (testpaths: test/)"
# Backstop for a hang outside any one test (pytest-timeout covers each test; see pyproject.toml).
guard=()
if command -v timeout >/dev/null 2>&1; then
    guard=(timeout --foreground --kill-after=60 "${MK_TEST_TIMEOUT:-4800}")
fi
pytest_status=0
"${guard[@]}" python -m pytest "$@" </dev/null || pytest_status=$?
[ "$pytest_status" -ne 124 ] || echo "[test] pytest did not finish within ${MK_TEST_TIMEOUT:-4800} s" >&2

if [ "$ruff_status" -ne 0 ] || [ "$pytest_status" -ne 0 ]; then
    echo "[test] FAILED: ruff exit $ruff_status, pytest exit $pytest_status" >&2
    exit 1
fi
echo "[test] ruff and pytest passed"
