"""
What answers at an address, asked by ``scan``, ``doctor`` and before a command's first write.

The questions and their answers are :mod:`drive_bridge.devices.identification`; here is
its seam over the CLI's open port (:class:`RunnerProbes`: a probe device of each family,
built from the bus settings as the node would build it, on a transaction runner another
session opened), and the words a command says when the answer is another family.
"""

import time
from typing import Any, Dict, Optional, Tuple

from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.runner import run_poll, TransactionRunner
from drive_bridge.config import model as cfg
from drive_bridge.devices import identification
from drive_bridge.devices.contracts import DeviceProfile, DeviceReading
from drive_bridge.devices.identification import Answer
from drive_bridge.errors import ConfigError, LinkDown
from drive_bridge.protocol.requests import Request
from drive_bridge.tools.cli_target import CliError
from drive_bridge.transport.protocols import PROTOCOLS


class RunnerProbe:
    """A probe device of one family at an address, on an open runner (a :class:`Probe`)."""

    def __init__(self, config: cfg.BridgeConfig, runner: TransactionRunner):
        self.config = config
        self.runner = runner
        self.record = BusDevice(config.devices[0].make_spec(), time.monotonic())

    @property
    def profile(self) -> DeviceProfile:
        """Return the probe's profile."""
        return self.record.profile

    def poll(self) -> DeviceReading:
        """Run one whole poll cycle (a lost read repeated as the probe's retries allow)."""
        return run_poll(self.runner, self.record, self.config.timing.retries)

    def read(self, request: Request) -> Any:
        """Run ``request`` once."""
        return self.runner.transact(self.record, request)

    def sends(self, request_type: type) -> bool:
        """Return whether the bus's protocol carries requests of ``request_type``."""
        return request_type in PROTOCOLS[self.config.link.protocol].requests


class RunnerProbes:
    """One address of a bus on an open runner, as identification asks it (a ProbeLine)."""

    def __init__(self, bus: Dict[str, Any], address: int, runner: TransactionRunner,
                 retries: int = 0):
        self.bus = bus
        self.address = address
        self.runner = runner
        self.retries = retries  # scan: none, silence at an address means nobody is there

    @property
    def protocol(self) -> str:
        """Return the bus protocol's name."""
        return self.bus.get('protocol', 'modbus_rtu')

    def probe(self, family: str) -> Optional[RunnerProbe]:
        """Return a probe device of ``family`` at the address, or None."""
        values = {'family': family, 'address': self.address,
                  'model': 'vlt6000' if family == 'vlt' else 'auto'}
        try:
            config = cfg.build_config(dict(self.bus, devices=['probe'], retries=self.retries),
                                      {'probe': values})
        except ConfigError:
            return None  # e.g. an MCD cannot sit at this address
        return RunnerProbe(config, self.runner)


def identify(bus: Dict[str, Any], address: int, runner: TransactionRunner,
             retries: int = 0) -> Optional[Answer]:
    """
    Return what answers at ``address``, or None if nothing does (reads only).

    As :func:`drive_bridge.devices.identification.identify` tells it; a reply lost
    ``retries`` times over is silence (``scan`` gives none, a check before a write the
    bus's). A port that is gone is a CliError.
    """
    try:
        return identification.identify(RunnerProbes(bus, address, runner, retries))
    except LinkDown as error:
        raise CliError(str(error)) from None


def scan_families(bus: Dict[str, Any]) -> Tuple[str, ...]:
    """Return the families ``scan`` asks, in order, that can run on the bus's protocol."""
    return identification.families_asked(bus.get('protocol', 'modbus_rtu'))


def other_family(name: str, device: cfg.DeviceConfig, found: Answer, tail: str = '') -> str:
    """Return the line that says ``found`` answers at the device's address, not its family."""
    if found.family is None:
        return f'{name}: address {device.address}: {found.words} ({device.family} ' \
            f'included): check --address and --family{tail}'
    return f'{name}: address {device.address} answers as {found.words}, not as ' \
        f'family {device.family}: give --family {found.family} (or the right address){tail}'
