"""
What answers at an address: family, model, software version, or a VLT 5000/6000 option card.

Reads only, and no I/O here: the questions go to the wire through a seam the caller
implements (the CLI over its transaction runner, the node over its bus thread).

The seam (both are :class:`typing.Protocol`; nothing needs to inherit from them):

- :class:`ProbeLine`: one address on one line. ``protocol`` is the bus protocol's name
  (``modbus_rtu``, ``fc_protocol``, ...); ``probe(family)`` returns a :class:`Probe` of
  ``family`` at the address, or None when that family cannot sit there (an MCD behind
  switches 1-31 at address 40).
- :class:`Probe`: a device of one family at the address, configured with model ``auto``
  (VLT: ``vlt6000``, the card cannot tell). ``profile`` is its
  :class:`~drive_bridge.devices.contracts.DeviceProfile`, which learns the model as it is
  polled; ``poll()`` runs one whole poll cycle now and returns the reading (a read lost or
  garbled may be repeated, as the line's retries allow); ``read(request)`` runs one request
  once; ``sends(request_type)`` tells whether the line's protocol carries that request.

Both raise the project's errors (:mod:`drive_bridge.errors`): :class:`NoResponse` for
silence, :class:`LinkDown` when the port is gone, :class:`DeviceException` for a refusal,
another :class:`TransportError`, :class:`ProtocolError` or :class:`ModelMismatch` for a
reply that does not fit. :func:`identify` treats silence at the first question as nobody
at the address, lets :class:`LinkDown` through, and takes any other failure as "not this
family". A device the node polls tells what it is in its readings' decoded fields (FC
type 15-40 and software version 15-43 in ``/diagnostics``), without a transaction of its own.
"""

from typing import Any, NamedTuple, Optional, Protocol, Tuple

from drive_bridge.devices.contracts import DeviceProfile, DeviceReading
from drive_bridge.devices.fc_profile_drive import COIL_STATUS, FcProfileDrive, PROCESS_COILS
from drive_bridge.devices.parameters import parameter_address
from drive_bridge.devices.registry import FAMILIES
from drive_bridge.errors import (
    DeviceException, LinkDown, ModelMismatch, NoResponse, ProtocolError, TransportError)
from drive_bridge.protocol.fc_profile import StatusWord
from drive_bridge.protocol.requests import ReadCoils, ReadRegisters, Request
from drive_bridge.protocol.words import coils_to_words

SCAN_FAMILIES = ('fc', 'mcd')  # asked in this order; then the VLT option card
# The families identify() can tell: checked before a write. Not lvsg: behind its gateway
# the starter's process image answers as no family the reads know.
IDENTIFIED_FAMILIES = SCAN_FAMILIES + ('vlt',)
# Exception codes only the VLT option card answers (its drive's FC-protocol error codes and
# its own 64-67, 255); a Modbus device answers 01-0B.
OPTION_CARD_CODES = frozenset({0, 17, 64, 65, 66, 67, 130, 131, 255})
VLT_COMMON_PARAMETER = 538  # the alarm word: both VLT 5000 and VLT 6000 have it
NOT_READABLE = 'not readable'  # how an FC profile's identity says a parameter was refused


class Probe(Protocol):
    """A device of one family at the address being asked; see the module docstring."""

    @property
    def profile(self) -> DeviceProfile:
        """Return the probe's device profile, which learns the model as it is polled."""

    def poll(self) -> DeviceReading:
        """Run one whole poll cycle of the profile now; return its reading."""

    def read(self, request: Request) -> Any:
        """Run ``request`` once and return its result."""

    def sends(self, request_type: type) -> bool:
        """Return whether the line's protocol carries requests of ``request_type``."""


class ProbeLine(Protocol):
    """One address on one line, as identification asks it; see the module docstring."""

    @property
    def protocol(self) -> str:
        """Return the bus protocol's name (``modbus_rtu``, ``fc_protocol``, ...)."""

    def probe(self, family: str) -> Optional[Probe]:
        """Return a probe of ``family`` at the address, or None if it cannot sit there."""


class Answer(NamedTuple):
    """What answers at an address, as :func:`identify` tells it."""

    family: Optional[str]  # None: something answers, but as none of the families asked
    words: str  # e.g. 'fc fc51, state ready'
    model: Optional[str] = None  # None: the reads cannot tell (VLT 5000 or 6000)
    software_version: str = ''  # where the family's map has it (FC par. 15-43); '' if not


def families_asked(protocol: str) -> Tuple[str, ...]:
    """Return the families :func:`identify` asks, in order, that run on ``protocol``."""
    return tuple(family for family in SCAN_FAMILIES if protocol in FAMILIES[family].protocols)


def identify(line: ProbeLine) -> Optional[Answer]:
    """
    Return what answers at the line's address, or None if nothing does.

    FC-series drives are asked for their type text (par. 15-40) first, then MCD starters
    for their product word (40007); then the address is probed as a VLT 5000/6000 option
    card (:func:`probe_option_card`). Silence at the first question ends the address.
    Reads only; :class:`LinkDown` is raised.
    """
    for family in families_asked(line.protocol):
        try:
            probe = line.probe(family)
            if probe is None:
                continue
            return family_answer(line.protocol, family, probe)
        except LinkDown:
            raise
        except NoResponse:
            return None  # nothing at this address: do not try the other families
        except (TransportError, ModelMismatch, ProtocolError, ValueError, IndexError):
            continue
    card = probe_option_card(line) if line.protocol in FAMILIES['vlt'].protocols else ''
    return Answer('vlt', card) if card else \
        Answer(None, 'something answers, but not as any supported family')


def family_answer(protocol: str, family: str, probe: Probe) -> Answer:
    """Poll ``probe`` once and return what it answers as; raise what the poll raises."""
    reading = probe.poll()
    unknown = unknown_drive_type(probe.profile, reading.state)
    if unknown:
        return Answer('vlt', unknown)
    model = probe.profile.model
    if model == 'auto':  # AP ASCII: the starter cannot tell its model
        return Answer(family, f'{family} (its model cannot be read over {protocol}: '
                              f'name it with --model), state {reading.state}')
    return Answer(family, f'{family} {model}, state {reading.state}', model,
                  software_version(probe.profile))


def software_version(profile: DeviceProfile) -> str:
    """Return the software version the profile read (FC par. 15-43), or ''."""
    if not isinstance(profile, FcProfileDrive):
        return ''
    version = profile.identity.get('software_version', '')
    return '' if version.startswith(NOT_READABLE) else version


def unknown_drive_type(profile: DeviceProfile, state: str) -> str:
    """Return what an FC-profile drive that does not tell its type is ('' if it does)."""
    if not isinstance(profile, FcProfileDrive) or profile.data.identify_parameter is None:
        return ''
    type_text = profile.identity.get('drive_type', '')
    if profile.data.model_from_type(type_text) is not None:
        return ''
    told = f'par. 15-40 reads {type_text!r}' if type_text and \
        not type_text.startswith(NOT_READABLE) else 'par. 15-40 not readable'
    return f'a drive that does not tell its FC type ({told}): a VLT 5000/6000? set family ' \
        f'vlt with model vlt5000 or vlt6000, state {state}'


def probe_option_card(line: ProbeLine) -> str:
    """
    Return what a VLT 5000/6000 option card at the line's address says, or ''.

    The card cannot tell which drive it sits in, so nothing model-specific is asked: the
    FC-profile status coils, then par. 538 (the alarm word, on both models). A refusal with
    one of the card's own codes (00 "no such parameter" ..., which no plain Modbus device
    answers) still marks the card. :class:`LinkDown` is raised.
    """
    probe = line.probe('vlt')
    if probe is None or not probe.sends(ReadCoils):
        return ''  # the option card speaks Modbus only
    try:
        coils = probe.read(ReadCoils(COIL_STATUS, PROCESS_COILS))
        status_word, _ = coils_to_words(coils[:PROCESS_COILS])
        try:
            probe.read(ReadRegisters(parameter_address(VLT_COMMON_PARAMETER), 2))
        except DeviceException as error:
            if error.code not in OPTION_CARD_CODES:
                return ''
    except LinkDown:
        raise
    except (TransportError, ProtocolError, ValueError, IndexError):
        return ''
    return 'vlt (VLT 5000/6000 option card: set model vlt5000 or vlt6000), state ' \
        f'{StatusWord(status_word).state(None, False)}'
