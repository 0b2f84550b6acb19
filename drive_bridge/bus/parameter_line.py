"""
Parameter access on the bus thread: each device's ParameterService over the bus's line.

Every parameter access of the bus (the node's device parameters, ``BusMaster.read_parameter``
and ``write_parameter``) is a :class:`~drive_bridge.bus.jobs.ParameterServiceJob`: a function
of the device's :class:`~drive_bridge.devices.parameter_service.ParameterService`, run here
between two transactions of the bus, so the checks, the plan and the read-back are the
CLI's. :class:`BusDeviceLine` is that service's
:class:`~drive_bridge.devices.parameter_service.DeviceLine` on the bus:

- ``writes_allowed`` is the device's motor-state owner's, as it is at that moment (a
  monitor-only device: the service refuses every plan that writes before anything of it is
  sent, and the transaction runner refuses each write again);
- ``run`` sends each request through the bus's transaction runner (gap, monitor-only guard,
  statistics), once (a write is never repeated, nor is a read: the caller reads again). A
  refusal by the device is a CommandRefused in words, ``rejected by <device>: <explanation>``
  (the profile's text, with the detail read where the profile has one); a LinkDown takes
  the link down (every device offline) and passes on; every other failure passes on as it
  is. After a failure nothing more of the job is sent;
- ``check_before_writing`` does nothing: the bus's polls know the device (a job is taken
  only while the device is online);
- ``resolve_model`` answers from the polls (model ``auto``: as read, where the family
  reports it).

:class:`ParameterLines` keeps one line and service per device and runs the jobs. What a
job's function returns, or raises, resolves its future; a failure that is none of the
project's errors from the transport is a bug: it is raised on (the bus reports itself
offline and reopens the link, as after any internal error).
"""

from typing import Any, Dict, List, Optional, Sequence, Tuple

from drive_bridge.bus.device import BusDevice
from drive_bridge.bus.jobs import ParameterServiceJob
from drive_bridge.bus.seams import LinkState, Transactions
from drive_bridge.devices.parameter_service import ParameterService
from drive_bridge.errors import (
    CommandRefused, DeviceException, LinkDown, MonitorOnly, TransportError)
from drive_bridge.protocol.requests import Request


class BusDeviceLine:
    """One device's way to the wire on the bus thread; see the module docstring."""

    def __init__(self, device: BusDevice, runner: Transactions, link: LinkState):
        self.device = device
        self.runner = runner
        self.link = link
        self.failed = ''  # why the job in progress sends nothing more ('' while it may)
        self.unexpected: Optional[Exception] = None  # a bug of the transport, raised on

    @property
    def writes_allowed(self) -> bool:
        """Return False for a monitor-only device (``allow_control`` false now)."""
        return self.device.owner.writes_allowed

    def begin(self) -> None:
        """Start a job: nothing failed yet."""
        self.failed = ''
        self.unexpected = None

    def run(self, requests: Sequence[Request], doing: str) -> List[Any]:
        """Run ``requests`` in order, once each; see the module docstring."""
        if self.failed:
            raise CommandRefused(f'{doing} not sent: {self.failed}')
        device = self.device
        results = []
        for request in requests:
            try:
                results.append(self.runner.transact(device, request))
            except DeviceException as error:
                self.failed = f'{device.name} refused {request.describe()}'
                raise CommandRefused(f'rejected by {device.name}: '
                                     f'{self.runner.explain(device, error)}') from None
            except (TransportError, MonitorOnly) as error:
                self.failed = str(error)
                if isinstance(error, LinkDown):
                    self.link.lost(str(error))
                raise
            except Exception as error:  # noqa: B902 - a bug below: the bus recovers from it
                self.failed = f'internal error ({type(error).__name__}: {error})'
                self.unexpected = error
                raise
        return results

    def check_before_writing(self) -> None:
        """Do nothing: the bus's polls know the device (it is online)."""

    def resolve_model(self) -> str:
        """Return the model as the polls know it (the device is online: it was polled)."""
        return self.device.profile.model


class ParameterLines:
    """Each device's line and parameter service, and the jobs run on them (bus thread)."""

    def __init__(self, runner: Transactions, link: LinkState):
        self.runner = runner
        self.link = link
        self._services: Dict[str, Tuple[BusDeviceLine, ParameterService]] = {}

    def service(self, device: BusDevice) -> Tuple[BusDeviceLine, ParameterService]:
        """Return the line and the parameter service of ``device`` (made at its first job)."""
        made = self._services.get(device.name)
        if made is None or made[0].device is not device:
            line = BusDeviceLine(device, self.runner, self.link)
            made = self._services[device.name] = (
                line, ParameterService(device.name, device.profile, line))
        return made

    def run(self, job: ParameterServiceJob) -> None:
        """Run the job's function of the device's service, unless its caller gave it up."""
        if not job.future.set_running_or_notify_cancel():
            return  # cancelled before it reached the wire: never sent
        line, service = self.service(job.device)
        line.begin()
        try:
            result = job.action(service)
        except Exception as error:  # noqa: B902 - the caller's answer; the bus goes on
            job.future.set_exception(error)
            if line.unexpected is not None:
                raise line.unexpected
            return
        job.future.set_result(result)
