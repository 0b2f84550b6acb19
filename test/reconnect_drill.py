"""
Reconnect drills against the simulators: the bus master must recover with no restart.

Three drills, each a number of cycles in a row, the bus master on its own thread as in the
node:

- ``pty``: the serial adapter is unplugged (the pty and its symlink vanish) and plugged in
  again; an FC 51 and an MCD 500 on the line. The FC 51's comms timeout (par. 8-03) is
  spoiled while unplugged, so each recovery must send the set-up writes again.
- ``power``: the FC 51 power-cycles: silent, then back as a fresh drive with par. 8-03 at
  its factory value; the MCD 500 on the same line keeps running.
- ``tcp``: a Modbus TCP gateway (an MCD 202 behind a Profibus gateway) restarts: its
  listener and connections close, then it listens again on the same port.

Each cycle measures how long the bridge took to report the loss (``offline`` event) and,
from the moment the link or device was back, how long until it reported the device
``online`` again with its set-up writes done.
"""

from dataclasses import dataclass, field
import os
import statistics
import tempfile
import threading
import time
from typing import Callable, Dict, List, Optional, Type

from drive_bridge.bus.events import BusEvent, DeviceOffline, DeviceOnline
from drive_bridge.bus.master import BusMaster
from drive_bridge.config.model import build_config
from drive_bridge.sim.devices import make_device, make_sim_server
from drive_bridge.sim.lvsg_gateway import make_lvsg_gateway

COMMS_TIMEOUT_S = 3.7  # written to the FC 51's par. 8-03 by the set-up writes
SPOILED_803 = 7  # 0.7 s: what the drill leaves in par. 8-03 while the link is down
DRILLS = ('pty', 'power', 'tcp')


@dataclass
class DrillReport:
    """Detection and recovery times of one drill, in seconds."""

    drill: str
    detect_s: List[float] = field(default_factory=list)
    recover_s: List[float] = field(default_factory=list)
    failures: List[str] = field(default_factory=list)

    def line(self) -> str:
        """Return the figures in one line."""
        if not self.recover_s:
            return f'{self.drill}: no cycle completed; {"; ".join(self.failures)}'
        return (f'{self.drill}: {len(self.recover_s)} cycles, loss reported after '
                f'{_summary(self.detect_s)}, recovered after {_summary(self.recover_s)}'
                + (f'; FAILURES: {"; ".join(self.failures)}' if self.failures else ''))


def _summary(values: List[float]) -> str:
    return (f'median {statistics.median(values) * 1000:.0f} ms / '
            f'max {max(values) * 1000:.0f} ms')


class EventLog:
    """Bus events with their times; waits for the next one of a kind."""

    def __init__(self):
        self.events: List[tuple] = []
        self.condition = threading.Condition()

    def __call__(self, event: BusEvent) -> None:
        with self.condition:
            self.events.append((time.monotonic(), event))
            self.condition.notify_all()

    def wait(self, device: str, kind: Type[BusEvent], after_s: float, timeout_s: float = 10.0,
             check: Callable[[], bool] = lambda: True) -> Optional[float]:
        """Return the time of the first ``kind`` event of ``device`` after ``after_s``."""
        deadline = time.monotonic() + timeout_s
        with self.condition:
            while True:
                for stamp, event in self.events:
                    if stamp >= after_s and event.device == device and type(event) is kind \
                            and check():
                        return stamp
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return None
                self.condition.wait(min(remaining, 0.05))


BUS_TIMING = {'timeout': 0.1, 'retries': 1, 'offline_after': 2, 'backoff_max': 0.5}


def _serial_config(port: str):
    devices = {'conv': {'family': 'fc', 'model': 'fc51', 'address': 1, 'poll_rate': 20.0,
                        'comms_timeout': COMMS_TIMEOUT_S, 'comms_timeout_function': 2},
               'pump': {'family': 'mcd', 'model': 'mcd500', 'address': 20, 'poll_rate': 10.0}}
    return build_config(dict(BUS_TIMING, protocol='modbus_rtu', port=port, parity='N',
                             devices=list(devices)), devices)


def _tcp_config(port: int):
    devices = {'mixer': {'family': 'lvsg', 'model': 'mcd202', 'address': 1, 'poll_rate': 20.0,
                         'gateway_input_register': 0, 'gateway_output_register': 100}}
    return build_config(dict(BUS_TIMING, protocol='modbus_tcp', host='127.0.0.1',
                             tcp_port=port, devices=list(devices)), devices)


def _fc_803(server, unit: int = 1) -> int:
    with server.lock:
        return server.devices[unit].model.parameters[803]


def run_drill(drill: str, cycles: int = 20, down_s: float = 0.3) -> DrillReport:
    """Run ``cycles`` of ``drill`` ('pty', 'power' or 'tcp') and return the figures."""
    if drill not in DRILLS:
        raise ValueError(f'unknown drill {drill!r}: allowed {", ".join(DRILLS)}')
    report = DrillReport(drill)
    with tempfile.TemporaryDirectory() as folder:
        if drill == 'tcp':
            server = make_lvsg_gateway({0: ('mcd202', 100, 'extended')})
            tcp_port = server.open_tcp()
            config = _tcp_config(tcp_port)
            device = 'mixer'
        else:
            server = make_sim_server({1: 'fc51', 20: 'mcd500'})
            link = os.path.join(folder, 'ttyUSB_sim')  # stable, as a udev rule makes one
            server.open_pty(link)
            config = _serial_config(link)
            device = 'conv'
        server.start()
        log = EventLog()
        master = BusMaster(config.make_transport(), [spec.make_spec()
                                                     for spec in config.devices],
                           config.timing, listener=log).start()
        try:
            _cycles(drill, cycles, down_s, server, master, log, device, report)
        finally:
            master.shutdown(stop_motors=False)
            server.stop()
    return report


def _cycles(drill: str, cycles: int, down_s: float, server, master: BusMaster, log: EventLog,
            device: str, report: DrillReport) -> None:
    setup_done = (lambda: _fc_803(server) == round(COMMS_TIMEOUT_S * 10)) \
        if drill != 'tcp' else (lambda: True)
    if log.wait(device, DeviceOnline, 0.0, check=setup_done) is None:
        report.failures.append('the device never came online')
        return
    tcp_port = server.tcp_port
    for cycle in range(cycles):
        lost_at = time.monotonic()
        _break(drill, server)
        offline_at = log.wait(device, DeviceOffline, lost_at)
        if offline_at is None:
            report.failures.append(f'cycle {cycle + 1}: the loss was never reported')
            return
        time.sleep(down_s)  # the cable stays out a while
        if drill != 'tcp':
            with server.lock:  # a drive that forgot its set-up while the bus was away
                server.devices[1].model.parameters[803] = SPOILED_803
        back_at = time.monotonic()
        _repair(drill, server, tcp_port)
        online_at = log.wait(device, DeviceOnline, back_at, check=setup_done)
        if online_at is None:
            report.failures.append(f'cycle {cycle + 1}: no recovery within 10 s')
            return
        if drill != 'tcp' and master.snapshot('pump').online is not True and \
                log.wait('pump', DeviceOnline, back_at) is None:
            report.failures.append(f'cycle {cycle + 1}: the other device did not recover')
            return
        report.detect_s.append(offline_at - lost_at)
        report.recover_s.append(online_at - back_at)


def _break(drill: str, server) -> None:
    if drill == 'pty':
        server.unplug()
    elif drill == 'power':
        server.power_off(1)
    else:
        server.close_tcp()


def _repair(drill: str, server, tcp_port: int) -> None:
    if drill == 'pty':
        server.replug()
    elif drill == 'power':
        fresh = make_device('fc51')
        fresh.model.parameters[803] = SPOILED_803
        server.power_on(1, fresh)
    else:
        server.open_tcp(port=tcp_port)


def run_all(cycles: int = 20) -> Dict[str, DrillReport]:
    """Run every drill."""
    return {drill: run_drill(drill, cycles) for drill in DRILLS}
