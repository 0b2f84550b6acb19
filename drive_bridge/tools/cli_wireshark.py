"""
``drive-bridge wireshark``: where the Wireshark dissectors are, and their installation.

The package ships Lua dissectors for the FC protocol, AP ASCII and the LVSG image
(``drive_bridge/wireshark/*.lua``, also in ``share/drive_bridge/wireshark/`` of a colcon or
apt install; ``docs/wireshark.md``). Without options the command lists them and says how to
load them; ``--install`` copies them to Wireshark's personal plugins folder (or
``--plugins-dir``), where Wireshark and tshark load them at start. No bus, no ROS.
"""

import argparse
from importlib import resources
import os
from typing import List

from drive_bridge.tools.cli_target import CliError, EXIT_FAILED, EXIT_USAGE

PERSONAL_PLUGINS_DIR = os.path.join('~', '.local', 'lib', 'wireshark', 'plugins')
DESCRIPTION = (
    'List the Wireshark Lua dissectors shipped with drive_bridge (danfoss_fc, '
    'danfoss_ap_ascii, the postdissector danfoss_lvsg), or copy them with --install to '
    "Wireshark's personal plugins folder (Help > About > Folders), where Wireshark and tshark "
    'load them at start. Existing files of the same name are replaced.')


def dissector_files() -> List[resources.abc.Traversable]:
    """Return the shipped ``.lua`` files, sorted by name."""
    folder = resources.files('drive_bridge') / 'wireshark'
    return sorted((entry for entry in folder.iterdir() if entry.name.endswith('.lua')),
                  key=lambda entry: entry.name)


def add_wireshark_command(commands) -> argparse.ArgumentParser:
    """Add ``wireshark`` to the subcommands of ``drive-bridge``; return its parser."""
    sub = commands.add_parser(
        'wireshark', help='list or install the Wireshark dissectors', description=DESCRIPTION,
        epilog='examples:\n  drive-bridge wireshark --install\n'
        '  tshark -X lua_script:$(drive-bridge wireshark --path danfoss_fc) -r trace.pcapng',
        formatter_class=argparse.RawDescriptionHelpFormatter)
    sub.set_defaults(function=command_wireshark)
    action = sub.add_mutually_exclusive_group()
    action.add_argument('--install', action='store_true',
                        help=f'copy the dissectors to --plugins-dir (default '
                        f'{PERSONAL_PLUGINS_DIR})')
    action.add_argument('--path', metavar='NAME',
                        help='print the path of one dissector (danfoss_fc, danfoss_ap_ascii, '
                        'danfoss_lvsg), for tshark -X lua_script:PATH')
    sub.add_argument('--plugins-dir', dest='plugins_dir', default=PERSONAL_PLUGINS_DIR,
                     metavar='DIR', help=f'where --install copies them (default '
                     f'{PERSONAL_PLUGINS_DIR})')
    return sub


def command_wireshark(args: argparse.Namespace, out) -> int:
    """List, locate or install the dissectors; return the exit status."""
    files = dissector_files()
    if args.path:
        return _print_path(files, args.path, out)
    if args.install:
        return _install(files, os.path.expanduser(args.plugins_dir), out)
    for entry in files:
        print(str(entry), file=out)
    print(f'load one with: tshark -X lua_script:FILE; or install them with: drive-bridge '
          f'wireshark --install ({PERSONAL_PLUGINS_DIR})', file=out)
    return 0


def _print_path(files, name: str, out) -> int:
    wanted = name if name.endswith('.lua') else f'{name}.lua'
    for entry in files:
        if entry.name == wanted:
            print(str(entry), file=out)
            return 0
    names = ', '.join(entry.name[:-len('.lua')] for entry in files)
    raise CliError(f'no dissector {name!r}: give one of {names}', EXIT_USAGE)


def _install(files, folder: str, out) -> int:
    try:
        os.makedirs(folder, exist_ok=True)
        for entry in files:
            target = os.path.join(folder, entry.name)
            with open(target, 'wb') as stream:
                stream.write(entry.read_bytes())
            print(f'installed {target}', file=out)
    except OSError as error:
        raise CliError(f'cannot install the dissectors in {folder}: {error.strerror}; give '
                       'a writable folder with --plugins-dir', EXIT_FAILED) from None
    print('restart Wireshark to load them; set the LVSG slaves in Edit > Preferences > '
          'Protocols > DANFOSS_LVSG (or tshark -o danfoss_lvsg.slaves:...)', file=out)
    return 0
