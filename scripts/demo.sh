#!/usr/bin/env bash
# The main job: set up (or refresh) the venv, then run the excavator demo.
# Arguments go to excavator_demo, e.g. `bash scripts/demo.sh --help`.
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$REPO/scripts/bootstrap.sh"
# shellcheck source=scripts/env.sh
. "$REPO/scripts/env.sh"
exec excavator_demo "$@"
