#!/usr/bin/env bash
# Run the whole test suite, what CI runs (.ci/run), and print each step's wall and CPU time.
# Every test function runs once, the ones marked pymodbus once more with pymodbus 3.6.9.
# The steps run one after another (docs/contributing.md says why not side by side):
#   first the steps that compute and have no deadlines
#     docs                        scripts/docs.sh (Sphinx, every warning an error)
#     colcon build, installed commands, then colcon test: the unit tier and the linters,
#                                 against the install space
#   then the tests with deadlines, one tier after another
#     integration tier            pytest in .venv (pymodbus 3.16), pytest-xdist workers
#     integration tier: realtime  the tests whose threads must run within milliseconds
#                                 (those marked pymodbus also in .venv-pymodbus369)
#     pymodbus 3.6.9              the other tests marked pymodbus, in .venv-pymodbus369
#     ROS tier                    pytest in .venv, pytest-xdist workers
# except on a free machine, where two pairs go side by side: the pymodbus 3.6.9 run beside
# the integration tier; the docs, the installed commands and the linters but flake8 (pep257,
# the import contracts) beside the realtime tests.
# A failing step does not stop the run: the other steps run, the table marks it FAILED and
# the script exits 1. Arguments go to the pytest runs of the checkout (scripts/test.sh -x).
# Workers per tier: UNIT_WORKERS, INTEGRATION_WORKERS, REALTIME_WORKERS, ROS_WORKERS; by
# default fewer where other work keeps the machine busy (docs/contributing.md says why).
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

# busy_cores: how many cores other processes keep busy, over one second (/proc/stat).
busy_cores() {
  local before after
  before=$(head -1 /proc/stat)
  sleep 1
  after=$(head -1 /proc/stat)
  awk -v before="$before" -v after="$after" -v cores="$(nproc)" 'BEGIN {
    n = split(before, b); split(after, a); total = 0; idle = 0
    for (i = 2; i <= 9 && i <= n; i++) { total += a[i] - b[i] }
    idle = (a[5] - b[5]) + (a[6] - b[6])
    printf "%.2f", (total > 0 ? (total - idle) / total * cores : 0) }'
}
# Workers per tier (docs/contributing.md says why). Where the machine is free, the integration
# tier takes seven workers and the ROS tier eight (their tests mostly wait: on a free machine
# they use 1.2 and 1.8 of its 2 cores); where other work keeps half a core or more busy when
# the run starts (a CI machine shared with other jobs), two and three: beside a CPU hog, four
# ROS workers starved a test's simulator past its 1 s reply timeout; the wire-bound tiers
# were tried with more than two only on a free machine. The load is sampled once, at the
# start.
busy=$(busy_cores)
if awk -v busy="$busy" 'BEGIN { exit !(busy >= 0.5) }'; then
  load_note="other work keeps $busy cores busy: fewer workers, one step at a time"
  machine_free=0
  default_wire_workers=2
  default_ros_workers=3
else
  load_note="the machine is free ($busy cores busy)"
  machine_free=1
  default_wire_workers=7
  default_ros_workers=8
fi
unit_workers=${UNIT_WORKERS:-2}
integration_workers=${INTEGRATION_WORKERS:-$default_wire_workers}
realtime_workers=${REALTIME_WORKERS:-3}
ros_workers=${ROS_WORKERS:-$default_ros_workers}
echo "== workers: integration $integration_workers, realtime $realtime_workers," \
  "ROS $ros_workers, unit $unit_workers ($load_note)"

run_started=$EPOCHREALTIME
workspace=$(mktemp -d)
steps="$workspace/steps"  # one line per step that ended: name, wall s, cpu s, FAILED
: > "$steps"

seconds_since() { awk -v from="$1" -v to="$EPOCHREALTIME" 'BEGIN { printf "%.1f", to - from }'; }
# children_cpu_s FILE: write the user+system CPU seconds of the children of this shell to
# FILE, from bash's `times` (in this shell: a pipe or $(...) would ask a subshell).
children_cpu_s() {
  times > "$1.times"
  awk 'NR == 2 {
    total = 0
    for (i = 1; i <= 2; i++) { split($i, t, /[ms]/); total += t[1] * 60 + t[2] }
    printf "%.1f", total }' "$1.times" > "$1"
}
# step NAME COMMAND...: run COMMAND, print and keep its wall and CPU time; return its status.
step() {
  local name=$1 started=$EPOCHREALTIME status cpu_file cpu_s
  shift
  echo "== $name"
  cpu_file=$(mktemp -p "$workspace")
  (
    "$@"
    status=$?
    children_cpu_s "$cpu_file"
    exit $status
  ) &
  wait $!
  status=$?
  cpu_s=$(cat "$cpu_file")
  local mark=''
  [ "$status" = 0 ] || mark='FAILED'
  printf '%-34s %7s %7s  %s\n' "$name" "$(seconds_since "$started")" "${cpu_s:-?}" "$mark" \
    >> "$steps"
  echo "== $name: $(seconds_since "$started") s wall, ${cpu_s:-?} s CPU${mark:+, $mark}"
  return $status
}
finish() {
  echo "== step times (s; CPU: user+system of the step's processes)"
  printf '   %-34s %7s %7s\n' step wall CPU
  sed 's/^/   /' "$steps"
  printf '   %-34s %7s\n' total "$(seconds_since "$run_started")"
  if grep -q 'FAILED$' "$steps"; then
    echo "== FAILED: $(grep 'FAILED$' "$steps" | awk '{ NF -= 3; print }' | paste -sd ',')"
  fi
  rm -rf "$workspace"
}
trap finish EXIT
# Ctrl-C or a TERM: stop everything this run started, at once (each step runs in the
# background and is waited for, and a trapped signal ends the wait). Without job control the
# background processes (the realtime step's pymodbus 3.6.9 run) ignore SIGINT, and
# would go on after the run has ended and its workspace is gone.
found=()
collect() {  # collect PID: add every process below PID to found (Linux /proc; no forks)
  local file child children
  for file in /proc/"$1"/task/*/children; do
    children=()
    { read -r -a children < "$file"; } 2> /dev/null
    for child in "${children[@]}"; do
      found+=("$child")
      collect "$child"
    done
  done
}
interrupted() {  # interrupted STATUS: stop what the run started, then exit with STATUS
  trap '' INT TERM
  echo "== interrupted: stopping what the run started"
  found=()
  collect $$
  [ ${#found[@]} -eq 0 ] || kill -TERM "${found[@]}" 2> /dev/null
  # Up to 5 s for them to end before the workspace goes: by their pids, as those whose
  # parent ended first are no longer below this shell.
  local pid tries left
  for tries in $(seq 50); do
    left=0
    for pid in "${found[@]}"; do
      [ -d "/proc/$pid" ] && left=1 && break
    done
    [ "$left" = 0 ] && break
    sleep 0.1
  done
  exit "$1"
}
trap 'interrupted 130' INT
trap 'interrupted 143' TERM

VENV="$root/.venv"
VENV369="$root/.venv-pymodbus369"
# Without its venvs nothing else can run.
step 'venvs' scripts/setup_venv.sh "$VENV" requirements-test.txt || exit 1
step 'venv (pymodbus 3.6.9)' scripts/setup_venv.sh "$VENV369" requirements-pymodbus369.txt \
  || exit 1
step 'venv (docs)' scripts/setup_venv.sh "$root/.venv-docs" requirements-docs.txt || exit 1

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

pytest_in() {  # pytest_in VENV ARGS...: quiet, no cache directory in the checkout
  local venv=$1
  shift
  "$venv/bin/python" -m pytest -q -p no:cacheprovider "$@"
}
echo "pymodbus $("$VENV/bin/python" -c 'import pymodbus; print(pymodbus.__version__)') in .venv," \
  "$("$VENV369/bin/python" -c 'import pymodbus; print(pymodbus.__version__)')" \
  'in .venv-pymodbus369'

# The integration tier, its realtime tests, the pymodbus 3.6.9 run. On a free machine the
# pymodbus 3.6.9 run goes beside the integration tier (both wait on the wire: 1.2 cores
# together), and the docs, the installed commands and the linters but flake8 (one core,
# about 20 s) beside the realtime tests, which pass beside a CPU hog as well; on a busy
# machine one after another.
wire_steps() {
  if [ "$machine_free" = 1 ]; then
    step 'integration, pymodbus 3.6.9 beside' integration_tests "$@"
    local beside_log="$workspace/beside.log" beside_pid
    compute_beside_realtime > "$beside_log" 2>&1 &
    beside_pid=$!
    step 'integration tier: realtime tests' realtime_tests "$@"
    # each step beside marks its own line FAILED; a lane that died before it could, here
    wait "$beside_pid" || printf '%-34s %7s %7s  %s\n' 'docs, installed commands, linters' \
      '?' '?' FAILED >> "$steps"
    echo '-- beside the realtime tests:'
    cat "$beside_log"
    return
  fi
  step 'integration tier' pytest_in "$VENV" -n "$integration_workers" --dist loadgroup \
    -m 'not realtime' test/integration "$@"
  step 'integration tier: realtime tests' realtime_tests "$@"
  step 'pymodbus 3.6.9: marked tests' pytest_in "$VENV369" -n "$integration_workers" \
    --dist loadgroup -m 'pymodbus and not realtime' test/unit test/integration "$@"
}
# pytest_beside_369 NAME ARGS369 ARGS...: pytest in .venv with ARGS and, beside it, in
# .venv-pymodbus369 with the arguments in the array named ARGS369; the second's output after
# the first's, under NAME; fails if either does.
pytest_beside_369() {
  local name=$1 log369="$workspace/$2.log" pid369 status
  local -n pytest369_args=$2
  shift 2
  pytest_in "$VENV369" "${pytest369_args[@]}" > "$log369" 2>&1 &
  pid369=$!
  pytest_in "$VENV" "$@"
  status=$?
  wait "$pid369" || status=1
  echo "-- $name, with pymodbus 3.6.9:"
  cat "$log369"
  return $status
}
# The integration tier and, beside it, the other tests marked pymodbus with pymodbus 3.6.9
# in two workers.
integration_tests() {
  local integration369=(-n 2 --dist loadgroup -m 'pymodbus and not realtime' test/unit
    test/integration "$@")
  pytest_beside_369 'beside it, the tests marked pymodbus (not realtime)' integration369 \
    -n "$integration_workers" --dist loadgroup -m 'not realtime' test/integration "$@"
}
# Tests whose threads must run within milliseconds: no CPU-bound workers beside them, at most
# one process that keeps one core busy (they pass beside a CPU hog): on a free machine the
# docs build, the installed commands and the linters but flake8, one after another. They
# wait on the clock, so a few of them share the machine: the realtime workers, and beside
# them one process that runs the ones marked pymodbus again with pymodbus 3.6.9 (three
# tests, about 15 s), one after another.
realtime_tests() {
  local realtime369=(-m 'pymodbus and realtime' test/integration "$@")
  pytest_beside_369 'the same marked pymodbus' realtime369 \
    -n "$realtime_workers" --dist loadgroup -m realtime test/integration "$@"
}

# The docs and the colcon workspace (build, installed commands, unit tier, linters).
mkdir -p "$workspace/src/drive_bridge"
git -C "$root" ls-files -z --cached --others --exclude-standard \
  | (cd "$root" && xargs -0 cp --parents -t "$workspace/src/drive_bridge")
workspace_colcon() { (cd "$workspace" && "$VENV/bin/colcon" --log-base log "$@"); }
# colcon_test MARKS: the unit tier and the linters the marker expression MARKS selects.
colcon_test() {
  workspace_colcon test --return-code-on-test-failure --event-handlers console_direct+ \
    --pytest-args -n "$unit_workers" -m "$1" --timeout 900 \
    && workspace_colcon test-result --all
}
# The linters but flake8 (pep257, the import contracts: one process) as colcon test runs
# them, in the workspace's copy of the package: every test marked so, wherever it is.
other_linters() {
  (cd "$workspace/src/drive_bridge" \
    && "$VENV/bin/python" -m pytest -q -p no:cacheprovider -m 'linter and not flake8' test)
}
compute_steps() {
  # Alone, before the tests with deadlines: beside them in the idle scheduling class (or at
  # nice 19) the babbling-line tests held every pty on the machine for 6-38 s, and at the
  # normal priority the babbler missed its pace (docs/contributing.md). On a free machine
  # the docs and the installed commands go beside the realtime tests instead (one core).
  [ "$machine_free" = 1 ] || step 'docs' scripts/docs.sh "$workspace/docs"
  if step 'colcon build' workspace_colcon build --event-handlers console_direct-; then
    built=1
    [ "$machine_free" = 1 ] || step 'installed commands' scripts/check_install.sh \
      "$workspace/install"
    # The unit tier and the linters run here only, against the install space; the
    # integration and ROS tiers run from the checkout only (docs/contributing.md).
    if [ "$machine_free" = 1 ]; then  # the other linters beside the realtime tests
      step 'colcon test: unit tier, flake8' colcon_test 'unit or flake8'
    else
      step 'colcon test: unit tier, linters' colcon_test 'unit or linter'
    fi
  fi
}
# On a free machine, beside the realtime tests: one process at a time, one core.
compute_beside_realtime() {
  local status=0
  step 'docs, beside the realtime tests' scripts/docs.sh "$workspace/docs" || status=1
  if [ "$built" = 1 ]; then
    step 'installed commands, beside them' scripts/check_install.sh "$workspace/install" \
      || status=1
  fi
  step 'pep257, import contracts, beside' other_linters || status=1
  return $status
}
built=0
compute_steps
wire_steps "$@"
# The ROS tier computes more than it waits (a node's start costs about 1 s of CPU), so it runs
# after the wire-bound steps, not beside them.
step 'ROS tier' pytest_in "$VENV" -n "$ros_workers" --dist loadgroup test/ros "$@"
if grep -q 'FAILED$' "$steps"; then exit 1; fi
