#!/usr/bin/env bash
# The main job: set up (or refresh) the venv, then run the excavator demo.
# Arguments go to excavator_demo, e.g. `bash scripts/demo.sh --help`.
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$REPO/scripts/bootstrap.sh"
user_domain="${ROS_DOMAIN_ID-}"
# shellcheck source=scripts/env.sh
. "$REPO/scripts/env.sh"
# Localhost discovery (env.sh) and, unless you set ROS_DOMAIN_ID, a free domain the demo reserves
# for itself (excavator_demo prints which), not env.sh's shared examples domain.
[ -n "$user_domain" ] || unset ROS_DOMAIN_ID
exec excavator_demo "$@"
