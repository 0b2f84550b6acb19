#!/usr/bin/env bash
# Check a colcon install space as `ros2 run drive_bridge <command>` uses it: every console
# script in <install>/drive_bridge/lib/drive_bridge, each one running from the installed
# package (not a development copy) with the install space's environment.
# Usage: scripts/check_install.sh INSTALL_DIR
set -euo pipefail
install=$(cd "${1:?install dir}" && pwd)
cd "$install"  # a drive_bridge/ in the caller's directory would shadow the installed one
lib="$install/drive_bridge/lib/drive_bridge"
for command in drive_bridge_node drive_bridge_sim drive-bridge drive_bridge_plot \
    drive_bridge_record drive_bridge_ctl; do
  [ -x "$lib/$command" ] || { echo "not installed: $lib/$command" >&2; exit 1; }
done
set +u  # colcon's setup.sh reads unset variables
. "$install/setup.sh"
set -u
for command in drive_bridge_sim drive-bridge drive_bridge_plot drive_bridge_record \
    drive_bridge_ctl; do
  "$lib/$command" --help > /dev/null || { echo "$lib/$command --help failed" >&2; exit 1; }
done
python=$(head -1 "$lib/drive_bridge_record" | sed 's/^#!//')
package=$("$python" -c 'import drive_bridge, os; print(os.path.dirname(drive_bridge.__file__))')
case "$package" in
  "$install"/*) ;;
  *) echo "the installed commands import drive_bridge from $package, not $install" >&2; exit 1;;
esac
ls "$install/drive_bridge/share/drive_bridge/package.xml" > /dev/null
echo "installed: $(ls "$lib" | tr '\n' ' ')(ros2 run drive_bridge <command>)"
