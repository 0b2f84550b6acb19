"""
Bytes and line time per poll: the Danfoss FC protocol against Modbus RTU, same drive data.

Both sides are computed from the encoders, not from formulas. Modbus RTU: the transactions
:class:`drive_bridge.devices.fc_profile_drive.FcProfileModbusDrive` plans for a started FC 51
today (one 0F write of coils 1-32, one 01 read of coils 33-64, one 03 read of 16-14, one rotating
readout), each request and reply encoded by :mod:`drive_bridge.protocol.rtu`; line time
with a 3.5-character gap before each frame. FC protocol: one telegram carrying control word,
reference, status word, main actual value and one parameter read (16-14), and, for the
like-for-like case, a second telegram for the rotating readout; line time with the
documented 2-character pause before each telegram. Drive response delays come on top of
the line time, once per transaction (FC: up to 20-50 ms documented; Modbus: par. 8-35).
Run: .venv/bin/python bench/fc_protocol_wire.py
"""

from typing import List, Tuple

from drive_bridge.devices import fc51 as fc_family
from drive_bridge.devices.contracts import FixedControl
from drive_bridge.devices.fc_profile_drive import FcProfileModbusDrive
from drive_bridge.protocol import fc_profile, fc_telegram as fcp, rtu
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.fc_telegram import FcTelegramRequest
from drive_bridge.protocol.requests import ReadCoils, ReadRegisters, WriteCoils

ADDRESS = 1
BAUDRATES = (9600, 19200)


def modbus_frames(transaction) -> Tuple[bytes, bytes]:
    """Return (request, reply) bytes of one Modbus transaction, both encoded."""
    if isinstance(transaction, WriteCoils):
        request = rtu.write_coils_request(ADDRESS, transaction.address,
                                          list(transaction.values))
        reply = rtu.RtuFrame(ADDRESS, rtu.WRITE_MULTIPLE_COILS, request.data[:4])
    elif isinstance(transaction, ReadCoils):
        request = rtu.read_coils_request(ADDRESS, transaction.address, transaction.count)
        packed = rtu.pack_coils([False] * transaction.count)
        reply = rtu.RtuFrame(ADDRESS, rtu.READ_COILS, bytes([len(packed)]) + packed)
    elif isinstance(transaction, ReadRegisters):
        request = rtu.read_registers_request(ADDRESS, transaction.address, transaction.count)
        reply = rtu.registers_response(ADDRESS, rtu.READ_HOLDING_REGISTERS,
                                       [0] * transaction.count)
    else:
        raise TypeError(transaction)
    return request.encode(), reply.encode()


def modbus_polls(count: int) -> List[List[Tuple[str, bytes, bytes]]]:
    """Return ``count`` consecutive polls of a started FC 51 as (key, request, reply)."""
    profile = FcProfileModbusDrive(fc_family.DATA, 'fc51')
    profile._identified = True  # past the one-off identification reads
    started = FixedControl(Command.START, 0x2000)  # the keepalive write is sent
    return [[(type(request).__name__, *modbus_frames(request))
             for request in cycle_requests(profile, started)] for _ in range(count)]


def cycle_requests(profile, control) -> list:
    """Return the requests of one poll cycle, answered with zeros."""
    requests = []
    cycle = profile.poll(control, 0.0)
    try:
        step = next(cycle)
        while True:
            requests.append(step.request)
            request = step.request
            if isinstance(request, ReadCoils):
                result = [False] * request.count
            elif isinstance(request, ReadRegisters):
                result = [0] * request.count
            else:
                result = None
            step = cycle.send(result)
    except StopIteration:
        return requests


def fc_exchange(request: FcTelegramRequest, double_word: bool) -> Tuple[bytes, bytes]:
    """Return (request, reply) bytes of one FC-protocol telegram and its value reply."""
    telegram = request.telegram(ADDRESS)
    ak = fcp.AK_REPLY_DOUBLE if double_word else fcp.AK_REPLY_WORD
    reply = fcp.reply_to(telegram, 0x0F07, 0x2000, ak, 102)
    return telegram.encode(), reply.encode()


def line_time_ms(exchanges, baudrate: int, gap_characters: float) -> float:
    """Return the line time of the exchanges: bytes plus a gap before every frame, 8E1."""
    characters = sum(len(request) + len(reply) + 2 * gap_characters
                     for request, reply in exchanges)
    return 1000 * characters * fcp.character_time_s(baudrate, 'E', 1)


def main() -> None:
    polls = modbus_polls(len(fc_family.READOUTS['fc51']) - 1)  # one full rotation
    print('Modbus RTU, one poll of a started FC 51 (FcProfileModbusDrive.poll):')
    for key, request, reply in polls[0]:
        print(f'  {key[:40]:40s} request {len(request):2d} B  reply {len(reply):2d} B')
    rotating = sorted({len(request) + len(reply) for poll in polls
                       for key, request, reply in poll[3:]})
    print(f'  rotating readouts over one rotation: {rotating} bytes per transaction')
    control = fcp.read_parameter_request(1614, control_word=fc_profile.START_WORD,
                                         reference=0x2000)
    one = [fc_exchange(control, double_word=True)]
    rotating_fc = fcp.read_parameter_request(1690, control_word=fc_profile.START_WORD,
                                             reference=0x2000)
    two = one + [fc_exchange(rotating_fc, double_word=True)]
    print(f'FC protocol telegram: request {len(one[0][0])} B, reply {len(one[0][1])} B')
    print()
    print('poll                                    tx  bytes   ms@9600  ms@19200  (8E1)')
    rows = [('FC: 1 telegram (CTW REF STW MAV 16-14)', one, fcp.GAP_CHARACTERS),
            ('FC: 2 telegrams (+ rotating readout)', two, fcp.GAP_CHARACTERS)]
    for index, poll in enumerate(polls):
        exchanges = [(request, reply) for _, request, reply in poll]
        rows.append((f'Modbus RTU poll {index + 1} ({poll[-1][0]})', exchanges, 3.5))
    for label, exchanges, gap in rows:
        total = sum(len(request) + len(reply) for request, reply in exchanges)
        times = [line_time_ms(exchanges, baudrate, gap) for baudrate in BAUDRATES]
        print(f'{label:40s} {len(exchanges):2d}  {total:5d}  {times[0]:8.1f}  {times[1]:8.1f}')


if __name__ == '__main__':
    main()
