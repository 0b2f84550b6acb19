#!/usr/bin/env bash
# Set everything up (venv, pinned ROS 2 Jazzy wheels, drive_bridge) and run the MCD 500 demo.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
VENV="$root/.venv"
"$root/scripts/setup_venv.sh" "$VENV" requirements-test.txt
. "$root/scripts/env.sh"
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-42}
exec "$VENV/bin/python" "$root/demo/mcd_demo.py"
