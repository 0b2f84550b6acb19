#!/usr/bin/env bash
# Run the whole test suite: unit, integration and ROS tiers with the pinned pymodbus, then
# the transport and integration tiers again with pymodbus 3.6.9 (Ubuntu 24.04's package).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
VENV="$root/.venv"
"$root/scripts/setup_venv.sh" "$VENV" requirements-test.txt
. "$root/scripts/env.sh"
export FASTRTPS_DEFAULT_PROFILES_FILE="$root/test/fastdds_test_profile.xml"
echo "== pymodbus $("$VENV/bin/python" -c 'import pymodbus; print(pymodbus.__version__)'): all tiers"
"$VENV/bin/python" -m pytest -q -p no:cacheprovider test "$@"

echo "== colcon build, the installed commands, colcon test --return-code-on-test-failure"
workspace=$(mktemp -d)
trap 'rm -rf "$workspace"' EXIT
mkdir -p "$workspace/src/drive_bridge"
git -C "$root" ls-files -z --cached --others --exclude-standard \
  | (cd "$root" && xargs -0 cp --parents -t "$workspace/src/drive_bridge")
(cd "$workspace" && "$VENV/bin/colcon" --log-base log build --event-handlers console_direct- \
  && "$root/scripts/check_install.sh" "$workspace/install" \
  && "$VENV/bin/colcon" --log-base log test --return-code-on-test-failure \
       --event-handlers console_direct- --pytest-args -m "unit or linter" \
  && "$VENV/bin/colcon" --log-base log test-result --all)

VENV369="$root/.venv-pymodbus369"
"$root/scripts/setup_venv.sh" "$VENV369" requirements-pymodbus369.txt
echo "== pymodbus $("$VENV369/bin/python" -c 'import pymodbus; print(pymodbus.__version__)'): unit and integration tiers"
"$VENV369/bin/python" -m pytest -q -p no:cacheprovider test/unit test/integration "$@"
