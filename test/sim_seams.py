"""
Fake seams of the devices/ services over a simulated device, without port or bus thread.

:class:`SimLine` is a :class:`drive_bridge.devices.parameter_service.DeviceLine` and
:class:`SimProbeLine` a :class:`drive_bridge.devices.identification.ProbeLine`: each request
goes as its RTU frame to the simulator's ``handle()``, and the reply is parsed as the bus
would parse it (an exception reply raises DeviceException, no reply NoResponse). Every
request sent is kept in ``sent``, in order, with the calls of the seam (``calls``).
"""

from typing import Any, List, Optional, Sequence

from drive_bridge.devices.contracts import DeviceProfile, DeviceReading, FixedControl
from drive_bridge.devices.registry import FAMILIES
from drive_bridge.errors import DeviceException, LinkDown, NoResponse
from drive_bridge.protocol.requests import Request
from drive_bridge.sim.devices import make_device
from drive_bridge.transport.protocols import PROTOCOLS


class SimWire:
    """One simulated device on a wire of its own; ``sent`` keeps every request."""

    def __init__(self, device, unit: int = 1):
        self.device = device  # None: nobody answers
        self.unit = unit
        self.sent: List[Request] = []
        self.link_down = False

    def transact(self, request: Request) -> Any:
        """Send ``request`` to the simulator; return the parsed reply or raise as the bus."""
        if self.link_down:
            raise LinkDown('port gone')
        self.sent.append(request)
        frame = request.frame(self.unit)
        reply = None if self.device is None else self.device.handle(frame, 0.0)
        if reply is None:
            raise NoResponse(f'no reply to {request.describe()}')
        if reply.function & 0x80:
            raise DeviceException(reply.data[0])
        return request.parse(frame, reply)

    def poll(self, profile: DeviceProfile) -> DeviceReading:
        """Run one whole poll cycle of ``profile``; a refused optional step goes back to it."""
        cycle = profile.poll(FixedControl(), 0.0)
        try:
            step = next(cycle)
            while True:
                try:
                    result = self.transact(step.request)
                except DeviceException as error:
                    if not step.optional:
                        raise
                    result = error
                step = cycle.send(result)
        except StopIteration as done:
            return done.value


class SimLine:
    """A DeviceLine over a simulated device (see the module docstring)."""

    def __init__(self, wire: SimWire, profile: DeviceProfile, writes_allowed: bool = True):
        self.wire = wire
        self.profile = profile
        self.writes_allowed = writes_allowed
        self.calls: List[str] = []  # 'run', 'check_before_writing', 'resolve_model', 'poll'
        self._polled = False

    @property
    def sent(self) -> List[Request]:
        """Return every request sent, in order."""
        return self.wire.sent

    def run(self, requests: Sequence[Request], doing: str) -> List[Any]:
        """Run ``requests`` in order."""
        self.calls.append('run')
        return [self.wire.transact(request) for request in requests]

    def check_before_writing(self) -> None:
        """Note the call (the CLI asks what answers at the address here)."""
        self.calls.append('check_before_writing')

    def resolve_model(self) -> str:
        """Return the model; with model auto, poll once first."""
        self.calls.append('resolve_model')
        if self.profile.configured_model == 'auto' and not self._polled:
            self.calls.append('poll')
            self.wire.poll(self.profile)
            self._polled = True
        return self.profile.model


class SimProbe:
    """A probe of one family over a SimWire."""

    def __init__(self, wire: SimWire, profile: DeviceProfile, protocol: str):
        self.wire = wire
        self.profile = profile
        self.protocol = protocol

    def poll(self) -> DeviceReading:
        """Run one whole poll cycle."""
        return self.wire.poll(self.profile)

    def read(self, request: Request) -> Any:
        """Run ``request`` once."""
        return self.wire.transact(request)

    def sends(self, request_type: type) -> bool:
        """Return whether the protocol carries ``request_type``."""
        return request_type in PROTOCOLS[self.protocol].requests


class SimProbeLine:
    """A ProbeLine at one address with one simulated device (or none) behind it."""

    def __init__(self, wire: SimWire, protocol: str = 'modbus_rtu',
                 families: Optional[Sequence[str]] = None):
        self.wire = wire
        self.protocol = protocol
        self.families = families  # the families that may sit at the address (None: all)
        self.probed: List[str] = []

    def probe(self, family: str) -> Optional[SimProbe]:
        """Return a probe of ``family`` (model auto; VLT vlt6000), or None if not allowed."""
        if self.families is not None and family not in self.families:
            return None
        self.probed.append(family)
        model = 'vlt6000' if family == 'vlt' else 'auto'
        profile = FAMILIES[family].make_profile(model, self.protocol, {})
        return SimProbe(self.wire, profile, self.protocol)


def sim_wire(model: Optional[str], unit: int = 1, **settings) -> SimWire:
    """Return a wire with a simulated ``model`` at ``unit`` (None: nobody there)."""
    return SimWire(None if model is None else make_device(model, now_s=0.0, **settings), unit)
