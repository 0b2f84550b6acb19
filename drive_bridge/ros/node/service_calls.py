"""
Service calls awaiting the bus: the bus's future handed to the coroutine that awaits it.

A Trigger service is a coroutine: it submits its command to the bus and awaits
:meth:`ServiceCalls.answer_of`, so the executor serves topics and timers meanwhile. The bus
resolves its ``concurrent.futures.Future`` on the bus thread; its callback only triggers a
guard condition, and on the executor thread :meth:`ServiceCalls._deliver` hands the outcome
to the coroutine's rclpy future. A call the bus leaves waiting past its give-up time is
answered there too: a command the bus has not taken yet is cancelled first, so it is never
sent; one already on its way is answered as "not confirmed". :meth:`ServiceCalls.answer_all`
answers every waiting call when the bus is closed: what was not yet sent is cancelled and
refused, what was on the wire is "not confirmed", never "refused".

A service that answered the last call of a closed bus is destroyed a grace time later
(:meth:`ServiceCalls.destroy_later`): rclpy hands the response to the DDS writer and returns,
and the writer sends it again until the client acknowledges it. Deleting the writer right
after lost the answer under load (a start in flight at a lifecycle shutdown: its caller never
heard back). A new configuration and the node's end destroy such services at once.
"""

from concurrent.futures import Future
import threading
import time
from typing import Callable, List, Optional

from drive_bridge.errors import CommandRefused, DriveBridgeError
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.task import Future as RosFuture
from rclpy.timer import Timer

# How long a service outlives its last answer: more than Fast DDS's heartbeat period (3 s),
# after which a reliable writer sends again what its reader has not acknowledged.
RESPONSE_GRACE_S = 5.0


class PendingCall:
    """A service call waiting for the bus: the bus's future and the one the service awaits."""

    def __init__(self, bus_future: Future, label: str, give_up_at_s: float):
        self.bus_future = bus_future
        self.label = label
        self.give_up_at_s = give_up_at_s
        self.ros_future = RosFuture()


class ServiceCalls:
    """The calls of one node waiting for its bus, and the guard that hands them the answers."""

    def __init__(self, node: Node, grace_s: float = RESPONSE_GRACE_S):
        self._node = node
        self._pending: List[PendingCall] = []
        self._lock = threading.Lock()
        self._grace_s = grace_s
        self._retired: List[Callable[[], None]] = []
        self._retire_timer: Optional[Timer] = None
        # Service coroutines stay "executing" while they await the bus: they and the guard
        # that hands them the bus's answers must not share a mutually exclusive group.
        self.callback_group = ReentrantCallbackGroup()
        self._answers = node.create_guard_condition(self._deliver,
                                                    callback_group=self.callback_group)
        self.on_waiting: Callable[[], None] = lambda: None  # a call began to wait (executor)

    async def answer_of(self, bus_future: Future, label: str, give_up_s: float) -> str:
        """Await the bus's answer (executor thread); raise its error, or ours on giving up."""
        call = PendingCall(bus_future, label, time.monotonic() + give_up_s)
        with self._lock:
            self._pending.append(call)
        self.on_waiting()
        bus_future.add_done_callback(lambda done: self._answers.trigger())
        if bus_future.done():
            self._answers.trigger()
        result = await call.ros_future
        if isinstance(result, BaseException):
            raise result
        return result

    def waiting(self) -> bool:
        """Return whether a call waits for the bus."""
        with self._lock:
            return bool(self._pending)

    def wake(self) -> None:
        """Look at the waiting calls soon: answer those the bus left waiting too long."""
        self._answers.trigger()

    def answer_all(self, reason: str) -> None:
        """
        Answer every waiting call now (the bus was closed); what was not sent never is.

        A call the bus had not taken is cancelled and refused with ``reason``; one the bus
        answered meanwhile gets that answer; one on the wire is not confirmed (a start may
        be running: it is no refusal).
        """
        with self._lock:
            pending, self._pending = self._pending, []
        for call in pending:
            if call.ros_future.done():
                continue
            if call.bus_future.cancel():
                call.ros_future.set_result(CommandRefused(f'{call.label}: {reason}'))
            elif call.bus_future.done():
                error = call.bus_future.exception()
                call.ros_future.set_result(error if error is not None
                                           else call.bus_future.result())
            else:
                call.ros_future.set_result(DriveBridgeError(
                    f'{call.label} not confirmed: {reason} while it was on the wire; it may '
                    'have been carried out (see /diagnostics)'))

    def destroy_later(self, destroy: Callable[[], None]) -> None:
        """Run ``destroy`` (of services that just answered) a grace time from now."""
        with self._lock:
            self._retired.append(destroy)
            if self._retire_timer is not None:
                return
            # The steady clock: a node's clock stands still with use_sim_time and no /clock.
            self._retire_timer = self._node.create_timer(
                self._grace_s, self.destroy_retired, callback_group=self.callback_group,
                clock=Clock(clock_type=ClockType.STEADY_TIME))

    def destroy_retired(self) -> None:
        """Destroy now what waits for its grace time (a new configuration, the node's end)."""
        with self._lock:
            timer, self._retire_timer = self._retire_timer, None
            retired, self._retired = self._retired, []
        if timer is not None:
            self._node.destroy_timer(timer)
        for destroy in retired:
            destroy()

    def _deliver(self) -> None:
        """Hand the bus's answers to the waiting services (executor thread)."""
        now = time.monotonic()
        with self._lock:
            pending, self._pending = self._pending, []
        for call in pending:
            if call.bus_future.done():
                error = call.bus_future.exception()
                call.ros_future.set_result(error if error is not None
                                           else call.bus_future.result())
            elif now > call.give_up_at_s:
                self._give_up(call)
            else:
                with self._lock:
                    self._pending.append(call)

    @staticmethod
    def _give_up(call: PendingCall) -> None:
        """Answer a call the bus did not resolve in time; a command not yet sent never is."""
        if call.bus_future.cancel():
            call.ros_future.set_result(CommandRefused(
                f'{call.label} not sent: the bus did not take it in time; it is never sent'))
        else:
            call.ros_future.set_result(DriveBridgeError(
                f'{call.label} not confirmed: the bus did not answer in time; it may be on '
                'the wire (see /diagnostics)'))
