"""
A device parameter's name as a ROS parameter: the manual's number and a mnemonic. No I/O.

``p<manual number>_<mnemonic>``: the number as the device's manual writes it with ``-`` as
``_`` and the table's name in lower case, words joined by ``_`` (FC 51 par. 3-41 Ramp 1
Ramp-up Time: ``p3_41_ramp_1_ramp_up_time``; VLT par. 104 Motor Frequency:
``p104_motor_frequency``; MCD 500 par. 1-4 Current Limit: ``p1_4_current_limit``). A name
is valid for rcl's ``-p NAME:=VALUE`` and for parameters files (every dot-separated part
starts with a letter or ``_``, and there are no dots), and maps back to its parameter
through the table it was made from (:func:`names_of`), never by parsing the number out of
it. A part of the name in parentheses (``Output Frequency Low Limit (Minimum Frequency)``)
is left out unless it is the whole name.
"""

import re
from typing import Dict, Iterable, Mapping, Optional
import unicodedata

from drive_bridge.devices.parameters import ParameterSpec

MAX_MNEMONIC_CHARACTERS = 48  # long names are cut at a word boundary below this
_PARENTHESES = re.compile(r'\([^)]*\)|\[[^\]]*\]')
_NOT_WORD = re.compile(r'[^a-z0-9]+')
# rcl's rule for a parameter name given with -p or in a params file (per dotted part).
VALID_NAME = re.compile(r'^[A-Za-z_][A-Za-z0-9_]*$')


def mnemonic(name: str) -> str:
    """
    Return ``name`` as lower-case words joined by ``_`` (``Ramp 1 Ramp-up Time``: ramp_1_...).

    Accents are dropped (``Français``: francais); text in parentheses is left out unless
    nothing else is left; bracketed units are kept as a word (``Motor Speed Low Limit [Hz]``:
    motor_speed_low_limit_hz); a long name is cut at a word boundary.
    """
    ascii_name = unicodedata.normalize('NFKD', name).encode('ascii', 'ignore').decode()
    kept = re.sub(r'\([^)]*\)', ' ', ascii_name)
    words = _words(kept) or _words(ascii_name)
    while len(words) > MAX_MNEMONIC_CHARACTERS and '_' in words:
        words = words.rsplit('_', 1)[0]
    return words[:MAX_MNEMONIC_CHARACTERS].strip('_')


def _words(text: str) -> str:
    return _NOT_WORD.sub('_', text.lower().replace('[', ' ').replace(']', ' ')).strip('_')


def designation(spec: ParameterSpec) -> str:
    """Return the number as the device's manual writes it (FC 3-41, VLT 104, MCD 500 1-4)."""
    return spec.label or str(spec.number)


def ros_name(spec: ParameterSpec) -> str:
    """Return the ROS parameter name of ``spec``: ``p<number with - as _>_<mnemonic>``."""
    number = 'p' + re.sub(r'[^0-9A-Za-z]+', '_', designation(spec)).strip('_')
    words = mnemonic(spec.name)
    return f'{number}_{words}' if words else number


def is_valid_name(name: str) -> bool:
    """Return whether rcl takes ``name`` with ``-p`` and in a parameters file."""
    return all(VALID_NAME.match(part) for part in name.split('.'))


def names_of(specs: Iterable[ParameterSpec]) -> Dict[str, int]:
    """
    Return ROS name -> parameter number of ``specs``, in the order given.

    Raise ValueError if two specs get the same name or a name is not valid for rcl: the
    table, not the user, would be wrong.
    """
    names: Dict[str, int] = {}
    for spec in specs:
        name = ros_name(spec)
        if not is_valid_name(name):
            raise ValueError(f'{spec.title}: {name!r} is no valid ROS parameter name')
        if name in names:
            raise ValueError(f'{spec.title}: {name!r} names parameter {names[name]} too')
        names[name] = spec.number
    return names


def number_of(name: str, names: Mapping[str, int]) -> Optional[int]:
    """Return the parameter number ``name`` stands for (None: not a device parameter)."""
    return names.get(name)
