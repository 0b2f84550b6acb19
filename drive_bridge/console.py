"""
What the package's terminal commands share: how they read a number, and how they end.

A number a user types (``drive-bridge set 3-41 1.5``, ``drive_bridge_ctl reference conv 40``,
``--timeout 2``) is a plain ASCII decimal: an optional sign, digits, an optional fraction and
an optional exponent (``1.5``, ``-12``, ``.5``, ``1e3``); an integer is an optional sign and
digits. Python's ``float()`` and ``int()`` also take ``1_5`` (15), full-width and other
Unicode digits (U+FF14, a full-width 4, is 4) and spaces around the text;
:func:`parse_number` and :func:`parse_integer` take none of them, so a typo for 1.5 is
refused instead of setting 15. ``nan`` and ``inf`` are read, for the caller to refuse with
its own reason.

Their exit when the reader of their output goes (``drive-bridge monitor ... | head -3``,
``drive_bridge_ctl echo ... | head -2``): once the reader has gone, the next write raises
``BrokenPipeError``. The command then ends as SIGPIPE would end a C program, with
:data:`EXIT_BROKEN_PIPE` and nothing on stderr, and points its stdout at /dev/null first, so
that Python's flush at exit raises nothing either (Python's note on SIGPIPE, in the
``signal`` module's documentation).

A command line they cannot take is refused in one line on stderr, with exit status
:data:`EXIT_USAGE` (:class:`OneLineParser`): argparse's own refusal prints the usage first,
several lines for the commands with many options, and the reason last.
"""

import argparse
import os
import re
import sys
from typing import Any, Optional, Sequence, Union

EXIT_BROKEN_PIPE = 141  # the reader of stdout went away: as a program SIGPIPE ended
EXIT_USAGE = 2  # the command line was refused (argparse's status)
_PARSER_THAT_RAN = '_one_line_parser'  # the namespace's note of the parser that ran last
_INTEGER = re.compile(r'[+-]?[0-9]+')
_NUMBER = re.compile(r'[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?')
_NOT_FINITE = re.compile(r'[+-]?(nan|inf|infinity)', re.IGNORECASE)
# Sphinx and MyST markup in a docstring: a role (:data:`X`, :class:`~a.B`, {ref}`x`) and a
# literal (``x``).
_ROLE = re.compile(r'(?::[a-z]+(?::[a-z]+)?:|\{[a-z-]+\})`(~?)([^`]*)`')
_LITERAL = re.compile(r'``(.+?)``', re.DOTALL)


class OneLineParser(argparse.ArgumentParser):
    """
    An argument parser that refuses a command line in one line, without the usage.

    An option that the chosen subcommand does not know is refused by that subcommand's
    parser (``drive-bridge status --bogus``: see ``drive-bridge status --help``), not by the
    top one, whose help does not list the subcommand's options.
    """

    def __init__(self, *args: Any, **kwargs: Any):
        """Make the parser; each parser of a command line marks itself as the one that ran."""
        super().__init__(*args, **kwargs)
        self.set_defaults(**{_PARSER_THAT_RAN: self})

    def parse_args(self, args: Optional[Sequence[str]] = None,
                   namespace: Optional[argparse.Namespace] = None) -> argparse.Namespace:
        """
        Parse as argparse does; refuse what is left over in one line.

        Left over after the subcommand: the subcommand refuses it (its help lists its
        options); before it (``drive-bridge --quiet status``): this parser does.
        """
        argv = list(sys.argv[1:] if args is None else args)
        parsed, extras = self.parse_known_args(argv, namespace)  # subparsers call it too
        parser = vars(parsed).pop(_PARSER_THAT_RAN, self)
        if extras:
            command = parser.prog.split()[-1]
            if parser is not self and command in argv and extras[0] in argv \
                    and argv.index(extras[0]) < argv.index(command):
                parser = self
            parser.error(f'unrecognized arguments: {" ".join(extras)}')
        return parsed

    def error(self, message: str):
        """Print why on one line (and where help is), then exit with :data:`EXIT_USAGE`."""
        reason = ' '.join(message.split())
        self.exit(EXIT_USAGE, f'{self.prog}: error: {reason} (see {self.prog} --help)\n')


def plain_text(text: str) -> str:
    """
    Return a docstring's text without Sphinx or MyST markup, for a command's ``--help``.

    A role keeps its title, else its target (the last part of a target written with ``~``);
    a literal keeps its text.
    """
    def role(match: 're.Match[str]') -> str:
        tilde, body = match.groups()
        if body.endswith('>') and '<' in body:  # `title <target>`
            return body.split('<')[0].strip()
        return body.rsplit('.', 1)[-1] if tilde else body
    return _LITERAL.sub(r'\1', _ROLE.sub(role, text))


def parse_integer(text: str) -> int:
    """Return ``text`` as an int if it is an optional sign and ASCII digits; else ValueError."""
    if not _INTEGER.fullmatch(text):
        raise ValueError(f'{text!r} is not a whole number (write ASCII digits, e.g. 12)')
    return int(text)


def parse_number(text: str) -> Union[int, float]:
    """
    Return ``text`` as a plain ASCII decimal number, or raise ValueError in one line.

    An int when ``text`` is an integer (``12``), else a float (``1.5``, ``1e3``). ``nan`` and
    ``inf`` (``1e400`` too) give NaN and infinity, for the caller to refuse with its reason.
    """
    if _INTEGER.fullmatch(text):
        return int(text)
    if not (_NUMBER.fullmatch(text) or _NOT_FINITE.fullmatch(text)):
        raise ValueError(f'{text!r} is not a plain decimal number (write e.g. 12, -1.5 or '
                         '1e3)')
    return float(text)


def integer_argument(text: str) -> int:
    """Return ``text`` read by :func:`parse_integer` (an argparse type)."""
    return parse_integer(text)


def number_argument(text: str) -> float:
    """Return ``text`` read by :func:`parse_number`, as a float (an argparse type)."""
    return float(parse_number(text))


# argparse names the type in its message: "argument --timeout: invalid float value: 'x'"
integer_argument.__name__ = 'int'
number_argument.__name__ = 'float'


def drop_stdout() -> None:
    """Point stdout at /dev/null, so that nothing more is written to a closed pipe."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # no descriptor behind sys.stdout
        pass
    finally:
        os.close(devnull)
