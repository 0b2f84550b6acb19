#!/usr/bin/env bash
# Create or reuse a venv and install drive_bridge with its pinned dependencies.
# Usage: scripts/setup_venv.sh VENV_DIR REQUIREMENTS_FILE [extra pip args...]
set -euo pipefail
venv=${1:?venv dir}; requirements=${2:?requirements file}; shift 2
root=$(cd "$(dirname "$0")/.." && pwd)
python=${PYTHON:-python3}
if ! "$python" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  echo "drive_bridge needs Python 3.11 or newer as '$python' (set PYTHON=...)" >&2; exit 1
fi
stamp="$venv/.drive_bridge_stamp"
want=$(cat "$root/$requirements" "$root/requirements.txt" "$root/setup.py" "$root/package.xml" \
  | sha256sum | cut -c1-16)
want="$want $* $("$python" --version 2>&1)"
if [ -x "$venv/bin/python" ] && [ "$(cat "$stamp" 2>/dev/null)" = "$want" ]; then
  exit 0
fi
echo "setting up $venv (pip install -r $requirements; about 30 s the first time)..." >&2
if ! "$python" -m venv "$venv" 2>/dev/null; then
  echo "cannot create a venv: on Debian/Ubuntu run: sudo apt install python3-venv" >&2; exit 1
fi
"$venv/bin/python" -m pip install --quiet --upgrade pip 2>&1 | grep -v '^WARNING: Location' >&2 || true
"$venv/bin/python" -m pip install --quiet -r "$root/$requirements" "$@" 2>&1 \
  | grep -v '^WARNING: Location' >&2 || true
"$venv/bin/python" -m pip install --quiet --no-deps -e "$root" > "$venv/install.log" 2>&1 \
  || { cat "$venv/install.log" >&2; exit 1; }
"$venv/bin/python" -c 'import pymodbus, serial, drive_bridge' \
  || { echo "install into $venv failed" >&2; exit 1; }
echo "$want" > "$stamp"
