#!/usr/bin/env bash
# Build the manual (docs/, Sphinx) with every warning an error and every internal reference
# checked: scripts/docs.sh [OUTPUT_DIR] (default build/docs; open OUTPUT_DIR/index.html).
# Uses its own venv, .venv-docs (requirements-docs.txt; no ROS needed).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
VENV="$root/.venv-docs"
"$root/scripts/setup_venv.sh" "$VENV" requirements-docs.txt
out=${1:-"$root/build/docs"}
doctrees=$(mktemp -d)
trap 'rm -rf "$doctrees"' EXIT
"$VENV/bin/python" -m sphinx -W --keep-going -n -E -q -b html -d "$doctrees" \
  "$root/docs" "$out"
echo "docs: $out/index.html"
