"""CRC-16/Modbus (polynomial 0xA001 reflected, initial 0xFFFF), sent low byte first."""


def _make_table() -> tuple:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_TABLE = _make_table()


def crc16_modbus(data: bytes) -> int:
    """Return the CRC-16/Modbus of ``data`` as an integer."""
    crc = 0xFFFF
    for byte in data:
        crc = (crc >> 8) ^ _TABLE[(crc ^ byte) & 0xFF]
    return crc


def append_crc(frame: bytes) -> bytes:
    """Return ``frame`` with its CRC appended, low byte first."""
    return frame + crc16_modbus(frame).to_bytes(2, 'little')


def crc_ok(frame: bytes) -> bool:
    """Return whether the last two bytes of ``frame`` are the CRC of the bytes before them."""
    return len(frame) >= 4 and crc16_modbus(frame[:-2]) == int.from_bytes(frame[-2:], 'little')
