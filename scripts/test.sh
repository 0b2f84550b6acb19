#!/usr/bin/env bash
# Run the whole test suite, what CI runs (.ci/run), and print each step's time. Every test
# function runs once, the ones marked pymodbus once more with pymodbus 3.6.9:
#   docs                          scripts/docs.sh (Sphinx, every warning an error)
#   colcon                        colcon build, the installed commands, then colcon test: the
#                                 unit tier and the linters, against the install space
#   integration tier, ROS tier    pytest in .venv (pymodbus 3.16), pytest-xdist workers
#   pymodbus 3.6.9                the tests marked pymodbus, in .venv-pymodbus369
# Arguments go to the pytest runs of the checkout (scripts/test.sh -x). Workers per tier:
# UNIT_WORKERS, INTEGRATION_WORKERS, ROS_WORKERS (docs/contributing.md says why these).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
unit_workers=${UNIT_WORKERS:-2}
integration_workers=${INTEGRATION_WORKERS:-2}
ros_workers=${ROS_WORKERS:-3}

step_times=()
current_step=
step_started=
run_started=$EPOCHREALTIME
seconds_since() { awk -v from="$1" -v to="$EPOCHREALTIME" 'BEGIN { printf "%.1f", to - from }'; }
# step NAME COMMAND...: run COMMAND; print and keep its time.
step() {
  local name=$1
  shift
  current_step=$name
  echo "== $name"
  step_started=$EPOCHREALTIME
  "$@"
  step_times+=("$(printf '%-34s %6s' "$name" "$(seconds_since "$step_started")")")
  echo "== $name: $(seconds_since "$step_started") s"
  current_step=
}
workspace=$(mktemp -d)
finish() {
  local code=$? line
  rm -rf "$workspace"
  if [ -n "$current_step" ]; then
    step_times+=("$(printf '%-34s %6s  FAILED' "$current_step" \
      "$(seconds_since "$step_started")")")
  fi
  echo "== step times (s)"
  for line in "${step_times[@]}"; do echo "   $line"; done
  printf '   %-34s %6s\n' total "$(seconds_since "$run_started")"
  if [ "$code" != 0 ]; then echo "== FAILED (exit $code) in: ${current_step:-set-up}"; fi
}
trap finish EXIT

VENV="$root/.venv"
VENV369="$root/.venv-pymodbus369"
step 'venvs' scripts/setup_venv.sh "$VENV" requirements-test.txt
step 'venv (pymodbus 3.6.9)' scripts/setup_venv.sh "$VENV369" requirements-pymodbus369.txt
step 'docs' scripts/docs.sh "$workspace/docs"

. "$root/scripts/env.sh"
export FASTRTPS_DEFAULT_PROFILES_FILE="$root/test/fastdds_test_profile.xml"
# Python caches compiled modules unless told not to (some images set PYTHONDONTWRITEBYTECODE):
# the run starts hundreds of Python processes (nodes, CLIs, workers), and each one would
# compile drive_bridge and the tests again, about 0.2 s of CPU each. The cache stays out of
# the checkout.
unset PYTHONDONTWRITEBYTECODE
export PYTHONPYCACHEPREFIX="$VENV/pycache"
# Each test process takes a free ROS domain of its own (test/ros_domain.py): an exported id
# would be one for all the runs below.
unset ROS_DOMAIN_ID

mkdir -p "$workspace/src/drive_bridge"
git -C "$root" ls-files -z --cached --others --exclude-standard \
  | (cd "$root" && xargs -0 cp --parents -t "$workspace/src/drive_bridge")
workspace_colcon() { (cd "$workspace" && "$VENV/bin/colcon" --log-base log "$@"); }
step 'colcon build' workspace_colcon build --event-handlers console_direct-
step 'installed commands' scripts/check_install.sh "$workspace/install"
# The unit tier and the linters run here only, against the install space; the integration
# and ROS tiers run below only, from the checkout (docs/contributing.md).
step 'colcon test: unit tier, linters' workspace_colcon test --return-code-on-test-failure \
  --event-handlers console_direct+ --pytest-args -n "$unit_workers" -m 'unit or linter'
workspace_colcon test-result --all

pytest_in() {  # pytest_in VENV ARGS...: quiet, no cache directory in the checkout
  local venv=$1
  shift
  "$venv/bin/python" -m pytest -q -p no:cacheprovider "$@"
}
echo "pymodbus $("$VENV/bin/python" -c 'import pymodbus; print(pymodbus.__version__)') in .venv"
step 'integration tier' pytest_in "$VENV" -n "$integration_workers" --dist loadgroup \
  -m 'not realtime' test/integration "$@"
# Tests whose threads must run within milliseconds, in one process with no workers beside it.
step 'integration tier: realtime tests' pytest_in "$VENV" -m realtime test/integration "$@"
step 'ROS tier' pytest_in "$VENV" -n "$ros_workers" test/ros "$@"
echo "pymodbus $("$VENV369/bin/python" -c 'import pymodbus; print(pymodbus.__version__)')" \
  'in .venv-pymodbus369'
step 'pymodbus 3.6.9: marked tests' pytest_in "$VENV369" -n "$integration_workers" \
  --dist loadgroup -m pymodbus test/unit test/integration "$@"
