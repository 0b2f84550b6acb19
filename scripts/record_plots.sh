#!/usr/bin/env bash
# Record a simulated soft start and FC 51 ramp through the node with drive_bridge_record and
# plot them into build/record_plots/ (options: --output DIR; --update-docs writes the
# manual's figures in docs/ instead).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
VENV="$root/.venv"
"$root/scripts/setup_venv.sh" "$VENV" requirements-test.txt
. "$root/scripts/env.sh"
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-43}
exec "$VENV/bin/python" "$root/demo/record_plots.py" "$@"
