"""Pick the transport for a bus: AP ASCII, the native RTU engine, or pymodbus."""

from drive_bridge.transport.link import LinkSettings

SERIAL_ENGINES = ('native', 'pymodbus')


def make_transport(settings: LinkSettings, serial_engine: str = 'native', nak_retries: int = 2,
                   address_lrc_includes_eot: bool = True):
    """
    Return the transport of ``settings``.

    AP ASCII uses :mod:`.ap_ascii` (``nak_retries``, ``address_lrc_includes_eot``). Modbus
    RTU on a serial port uses the native engine (:mod:`.serial_rtu`) unless
    ``serial_engine`` is ``pymodbus``; Modbus TCP and RTU over TCP use pymodbus.
    """
    if serial_engine not in SERIAL_ENGINES:
        raise ValueError(f'serial_engine must be one of {", ".join(SERIAL_ENGINES)}')
    if settings.protocol == 'ap_ascii':
        from drive_bridge.transport.ap_ascii import ApAsciiTransport
        return ApAsciiTransport(settings, nak_retries, address_lrc_includes_eot)
    if settings.protocol == 'modbus_rtu' and serial_engine == 'native':
        from drive_bridge.transport.serial_rtu import RtuSerialTransport
        return RtuSerialTransport(settings)
    from drive_bridge.transport.modbus import ModbusTransport
    return ModbusTransport(settings)
