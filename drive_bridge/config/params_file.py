"""
The parameters file: a ROS 2 parameters file read as rcl reads it, and written.

Knows YAML and rcl's typing of scalars, not what the settings mean (that is
:mod:`drive_bridge.config.model`): a file that cannot be read, is not UTF-8, not YAML, has a
key twice or is not a parameters file is refused here in one line naming the file.
"""

import math
import re
import sys
from typing import Any, Callable, Dict, List, Optional, Union

from drive_bridge.errors import ConfigError


def duplicate_key_loader():
    """Return a YAML loader that refuses a key given twice in one mapping, with its lines."""
    import yaml

    class UniqueKeyLoader(yaml.SafeLoader):
        """Load YAML safely, refusing duplicate keys."""

    def construct_mapping(loader, node, deep=False):
        seen: Dict[Any, int] = {}
        for key_node, _ in node.value:
            key = loader.construct_object(key_node, deep=deep)
            line = key_node.start_mark.line + 1
            if key in seen:
                raise ConfigError(f'key {key!r} is given twice (lines {seen[key]} and {line}): '
                                  'the second would silently win; keep one')
            seen[key] = line
        return yaml.SafeLoader.construct_mapping(loader, node, deep)

    UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
                                    construct_mapping)
    return UniqueKeyLoader


# rcl's parameters file parser (rcl_yaml_param_parser, parse.c get_value, Jazzy: rcl 9.2)
# types a plain (unquoted, untagged) scalar in this order: one of its boolean words; an integer
# if strtoll(text, base 0) takes the whole text within int64 (10, -3, 0x1A, 010 = 8); a double
# if strtod takes the whole text without a range error (1e-1, 1.0e-1, -2E3, 1.0e5, .5, inf,
# nan, 0x1p3, and .nan, .inf, -.inf); else text. PyYAML (YAML 1.1) reads 1e-1 and -2E3 as
# text, y/n as text, 1_000 and 1:30 as integers and 2024-01-02 as a date; rcl does not. So
# that a file means to drive-bridge what it means to the node (``parity: N`` is false to both,
# ``timeout: 5e-1`` is 0.5 to both), plain scalars are typed as rcl types them. Keys are names
# to rcl, whatever they read like; an empty or null-looking value stays None (rcl refuses an
# empty value, and reads ``null`` and ``~`` as text; both are refused by the node's checks).
RCL_BOOLEANS = dict.fromkeys(('Y', 'y', 'yes', 'Yes', 'YES', 'true', 'True', 'TRUE', 'on',
                              'On', 'ON'), True)
RCL_BOOLEANS.update(dict.fromkeys(('N', 'n', 'no', 'No', 'NO', 'false', 'False', 'FALSE',
                                   'off', 'Off', 'OFF'), False))
RCL_SPECIAL_DOUBLES = {f'{sign}.{word}': float(f'{sign or "+"}{word}') for sign in ('', '+', '-')
                       for word in ('inf', 'Inf', 'INF')}
RCL_SPECIAL_DOUBLES.update({f'.{word}': math.nan for word in ('nan', 'NaN', 'NAN')})
YAML_NULLS = ('', '~', 'null', 'Null', 'NULL')
RCL_BOOLEAN_TAG = 'tag:drive_bridge,2026:rcl_boolean'
RCL_NUMBER_TAG = 'tag:drive_bridge,2026:rcl_number'
YAML_STR_TAG = 'tag:yaml.org,2002:str'
INT64 = (-2 ** 63, 2 ** 63 - 1)
# What strtoll (base 0) and strtod take whole, after the optional sign.
STRTOLL_TEXT = re.compile(r'[+-]?(0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)\Z')
STRTOD_DECIMAL = re.compile(r'[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?\Z')
STRTOD_HEX = re.compile(r'([+-]?)0[xX](([0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)'
                        r'([pP][+-]?[0-9]+)?)\Z')
STRTOD_WORD = re.compile(r'[+-]?(inf|infinity|nan(\([0-9a-zA-Z_]*\))?)\Z', re.IGNORECASE)


def rcl_number(text: str) -> Optional[Union[int, float]]:
    """Return ``text`` as the number rcl reads in a plain scalar, or None if rcl reads text."""
    if text in RCL_SPECIAL_DOUBLES:
        return RCL_SPECIAL_DOUBLES[text]
    if STRTOLL_TEXT.match(text):
        digits = text.lstrip('+-')
        base = 16 if digits[:2] in ('0x', '0X') else 8 if digits.startswith('0') else 10
        value = (-1 if text.startswith('-') else 1) * int(digits, base)
        if INT64[0] <= value <= INT64[1]:
            return value  # else strtoll's range error: strtod reads it below
    if STRTOD_WORD.match(text):
        return float(text.split('(')[0])
    hexadecimal = STRTOD_HEX.match(text)
    if hexadecimal:
        value = float.fromhex(f'{hexadecimal.group(1)}0x{hexadecimal.group(2)}')
    elif STRTOD_DECIMAL.match(text):
        value = float(text)
    else:
        return None
    digits = text.lower().split('p' if hexadecimal else 'e')[0]
    if math.isinf(value) or (abs(value) < sys.float_info.min and digits.strip('+-0x.')):
        return None  # strtod's range error (overflow, or underflow of a non-zero value): text
    return value


def rcl_scalar_tag(text: str) -> Optional[str]:
    """Return the tag of a plain scalar as rcl types it (None: null, as YAML reads it)."""
    if text in YAML_NULLS:
        return None
    if text in RCL_BOOLEANS:
        return RCL_BOOLEAN_TAG
    return RCL_NUMBER_TAG if rcl_number(text) is not None else YAML_STR_TAG


def parameters_file_loader():
    """Return the loader of a parameters file: unique keys, and scalars typed as rcl types them."""
    import yaml
    base = duplicate_key_loader()

    class ParametersFileLoader(base):
        """Load a ROS 2 parameters file as the node reads it."""

        def resolve(self, kind, value, implicit):
            """Type a plain scalar as rcl does; anything else as YAML does."""
            if kind is yaml.ScalarNode and implicit[0]:
                tag = rcl_scalar_tag(value)
                if tag is not None:
                    return tag
            return super().resolve(kind, value, implicit)

    def construct_mapping(loader, node, deep=False):
        for key_node, _ in node.value:
            if isinstance(key_node, yaml.ScalarNode):
                key_node.tag = YAML_STR_TAG  # a key is a name to rcl, whatever it reads like
        return base.yaml_constructors[yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG](
            loader, node, deep)

    ParametersFileLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
                                         construct_mapping)
    ParametersFileLoader.add_constructor(
        RCL_BOOLEAN_TAG, lambda loader, node: RCL_BOOLEANS[loader.construct_scalar(node)])
    ParametersFileLoader.add_constructor(
        RCL_NUMBER_TAG, lambda loader, node: rcl_number(loader.construct_scalar(node)))
    return ParametersFileLoader


def load_yaml_file(path: str, label: str, loader: Optional[Callable[[], Any]] = None) -> Any:
    """
    Return the content of the YAML file ``path``, refusing a key given twice.

    Raises ConfigError in one line naming the file as ``label`` if it cannot be read, is not
    UTF-8 text (with the byte's offset), is not YAML (a control character: which, where),
    or has a key twice (with both lines). ``loader`` makes the YAML loader to use (default
    :func:`duplicate_key_loader`).
    """
    import yaml
    text = read_text_file(path, label)
    try:
        return yaml.load(text, Loader=(loader or duplicate_key_loader)())
    except ConfigError as error:
        raise ConfigError(f'{label}: {error}') from None
    except yaml.reader.ReaderError as error:  # no 'problem': its str() has a second line
        line = text.count('\n', 0, error.position) + 1
        raise ConfigError(f'{label} is not valid YAML at line {line}: control character '
                          f'U+{error.character:04X} at position {error.position} is not '
                          'allowed') from None
    except yaml.YAMLError as error:
        where = getattr(error, 'problem_mark', None)
        line = f' at line {where.line + 1}' if where is not None else ''
        raise ConfigError(f'{label} is not valid YAML{line}: '
                          f'{getattr(error, "problem", None) or error}') from None


def read_text_file(path: str, label: str) -> str:
    """Return the UTF-8 text of the file ``path``; raise ConfigError (one line, ``label``)."""
    try:
        with open(path, 'rb') as stream:
            content = stream.read()
    except OSError as error:
        raise ConfigError(f'cannot read {label}: {error.strerror}') from None
    try:
        return content.decode('utf-8')
    except UnicodeDecodeError as error:
        line = content.count(b'\n', 0, error.start) + 1
        raise ConfigError(f'{label} is not UTF-8 text: byte {content[error.start]:#04x} at '
                          f'line {line}, offset {error.start} (save it as UTF-8)') from None


def load_params_file(path: str) -> Dict[str, Dict[str, Any]]:
    """
    Return the node blocks of a ROS 2 parameters file: node key to ros__parameters.

    Raises ConfigError in one line for a file that is missing, not YAML, has a key twice,
    or is not a parameters file. Both forms are read: ``/**/drive_bridge:`` (or any node
    key) holding ``ros__parameters``, and the nested form of the ROS 2 docs
    (``line1:`` / ``drive_bridge:`` / ``ros__parameters:``), whose key is ``/line1/drive_bridge``.
    """
    content = load_yaml_file(path, f'the parameters file {path}', parameters_file_loader)
    blocks: Dict[str, Dict[str, Any]] = {}
    if isinstance(content, dict):
        _collect_blocks(content, [], blocks)
    if not blocks:
        raise ConfigError(f'the parameters file {path} must map a node name (such as '
                          '/**/drive_bridge) to a ros__parameters block')
    return blocks


def _collect_blocks(mapping: Dict[Any, Any], path: List[str],
                    blocks: Dict[str, Dict[str, Any]]) -> None:
    for key, value in mapping.items():
        if not isinstance(value, dict):
            continue
        parts = path + [str(key).strip('/')]
        if isinstance(value.get('ros__parameters'), dict):
            blocks['/' + '/'.join(part for part in parts if part)] = value['ros__parameters']
        else:
            _collect_blocks(value, parts, blocks)


def node_matches(key: str, node_fqn: str) -> bool:
    """Return whether a parameters-file node key applies to the node ``node_fqn`` (as rcl)."""
    if key in ('/**', '**'):
        return True
    pattern = '^' + re.escape(key.rstrip('/')).replace(r'/\*\*', '(/[^/]+)*').replace(
        r'\*\*', '.*').replace(r'\*', '[^/]+') + '$'
    return re.match(pattern, node_fqn) is not None


def check_params_files(argv: List[str]) -> None:
    """Raise ConfigError, in one line, for a ``--params-file`` that cannot be used."""
    for position, argument in enumerate(argv):
        if argument == '--params-file' and position + 1 < len(argv):
            load_params_file(argv[position + 1])


def select_block(path: str, node: Optional[str] = None) -> Dict[str, Any]:
    """
    Return the parameters of the block for node ``node`` (its full name), or the only one.

    With several blocks and no ``node``, or no block matching it, raise ConfigError naming
    the blocks there are.
    """
    blocks = load_params_file(path)
    if node is not None:
        fqn = node if node.startswith('/') else '/' + node
        matching = [key for key in blocks if node_matches(key, fqn)]
    else:
        matching = list(blocks)
    if len(matching) != 1:
        what = f'for node {node}' if node else 'and no --node was given'
        raise ConfigError(f'the parameters file {path} has {len(matching)} blocks {what}: '
                          f'it has {", ".join(blocks)}; name one with --node')
    return blocks[matching[0]]


def write_params_file(path: str, bus: Dict[str, Any], devices: Dict[str, Dict[str, Any]],
                      node_key: str = '/**/drive_bridge') -> str:
    """
    Write a node parameters file (bus settings, ``devices`` and one block per device).

    Every string is quoted, as ROS's YAML parser needs (an unquoted N is false there).
    """
    import yaml

    class QuotingDumper(yaml.SafeDumper):
        """Quote every string."""

    QuotingDumper.add_representer(
        str, lambda dumper, value: dumper.represent_scalar('tag:yaml.org,2002:str', value,
                                                           style="'"))
    parameters = dict(bus, devices=list(devices), **devices)
    with open(path, 'w') as stream:
        yaml.dump({node_key: {'ros__parameters': parameters}}, stream, Dumper=QuotingDumper,
                  sort_keys=False)
    return str(path)
