"""
The LVSG process image of one MCD 200 as a DP-master gateway holds it. No I/O.

Where the input and output bytes sit in the gateway's Modbus registers and which byte of a
register comes first are the gateway's configuration; the output image (the control bits and
the extended module's parameter request) is what the gateway writes to the slave. The
profile (:class:`~drive_bridge.devices.lvsg.LvsgProfile`) decides what goes in it; this
collaborator says how it travels and keeps the control bits the gateway holds.
"""

from dataclasses import replace
from typing import List, Optional

from drive_bridge.protocol import lvsg
from drive_bridge.protocol.commands import Command
from drive_bridge.protocol.lvsg import Control
from drive_bridge.protocol.requests import ReadRegisters, Request, WriteRegister, WriteRegisters
from drive_bridge.protocol.words import bytes_to_registers, registers_to_bytes


class GatewayImage:
    """The input and output images in the gateway's registers, and the control bits held."""

    def __init__(self, input_register: int = 0, output_register: int = 0,
                 byte_order: str = 'big', extended: bool = True):
        self.input_register = input_register
        self.output_register = output_register
        self.byte_order = byte_order
        self.extended = extended
        self.input_bytes = lvsg.EXTENDED_INPUT_BYTES if extended else lvsg.BASIC_INPUT_BYTES
        self.output_bytes = lvsg.EXTENDED_OUTPUT_BYTES if extended else \
            lvsg.BASIC_OUTPUT_BYTES
        self.image: Optional[Control] = None  # the gateway's control bits (None: not read yet)

    @property
    def input_registers(self) -> int:
        """Return how many registers hold the input bytes."""
        return (self.input_bytes + 1) // 2

    @property
    def output_registers(self) -> int:
        """Return how many registers hold the output bytes."""
        return (self.output_bytes + 1) // 2

    @property
    def fwd_run(self) -> bool:
        """Return whether the gateway holds Fwd Run (False while not read yet)."""
        return bool(self.image and self.image.fwd_run)

    @property
    def quick_stop(self) -> bool:
        """Return whether the gateway holds Quick Stop (False while not read yet)."""
        return bool(self.image and self.image.quick_stop)

    def forget(self) -> None:
        """Forget the control bits: after a reconnect the output image is read again."""
        self.image = None

    def read_back(self) -> ReadRegisters:
        """Return the read of the output image (first contact)."""
        return ReadRegisters(self.output_register, self.output_registers)

    def adopt(self, result: object) -> None:
        """Take the output image read back (registers), or all bits clear if it failed."""
        if isinstance(result, list):
            control = Control.decode(registers_to_bytes(result, self.output_bytes,
                                                        self.byte_order))
        else:  # the gateway cannot read its outputs back: take all bits as clear
            control = Control()
        self.image = replace(control, reset=False)

    def read_input(self) -> ReadRegisters:
        """Return the read of the input image."""
        return ReadRegisters(self.input_register, self.input_registers)

    def decode_input(self, registers: List[int]) -> lvsg.Status:
        """Return the status the input image's registers carry."""
        return lvsg.decode_status(registers_to_bytes(registers, self.input_bytes,
                                                     self.byte_order))

    def write(self, control: Control, parameter_request: int) -> Request:
        """Return the write of the whole output image carrying ``control`` and the request."""
        registers = bytes_to_registers(
            replace(control, parameter_request=parameter_request).encode(self.extended),
            self.byte_order)
        if len(registers) == 1:
            return WriteRegister(self.output_register, registers[0])
        return WriteRegisters(self.output_register, tuple(registers))

    def request_write(self, parameter_request: int) -> WriteRegister:
        """Return the write of the register holding the parameter request (output byte 2)."""
        image = self.write(self.image or Control(), parameter_request)  # extended: two registers
        return WriteRegister(self.output_register + 1, image.values[1])

    def describe(self, steady: Optional[Command]) -> str:
        """Return the control bits the gateway holds, in words."""
        image = self.image
        if image is None:
            return 'not read yet'
        bits = [name for name, on in (('Fwd Run', image.fwd_run),
                                      ('Quick Stop', image.quick_stop)) if on]
        owner = 'written by the bridge' if steady is not None else 'as read back'
        return f'{", ".join(bits) or "no control bits"} ({owner})'
