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

VENV369="$root/.venv-pymodbus369"
"$root/scripts/setup_venv.sh" "$VENV369" requirements-pymodbus369.txt
echo "== pymodbus $("$VENV369/bin/python" -c 'import pymodbus; print(pymodbus.__version__)'): unit and integration tiers"
"$VENV369/bin/python" -m pytest -q -p no:cacheprovider test/unit test/integration "$@"
