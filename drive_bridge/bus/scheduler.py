"""
The scheduling step: one transaction or none, chosen just before it can go.

Each step of :meth:`BusScheduler.run_once` is one transaction or none: a waiting job (stops
first, then other commands, parameters and set-up writes), else the next step of the poll
cycle in progress, else the first step of the next device that is due. So a command goes
on the wire between two transactions of a poll, never later than the one on the wire when
it arrived: the next step is chosen only :data:`CHOICE_LEAD_S` before the inter-frame gap
ends, so a command that comes in the gap goes first. While the link is down nothing is
sent: every waiting job is answered at once, and the link is reopened after its backoff.

:meth:`~BusScheduler.run_once` has no waiting of its own (it returns how long to wait), so
unit tests drive it with a fake clock and a fake transport; the master runs it on a thread.

Events (readings, changes of state) go to the listener in the order they happened, from the
bus thread, while the next request is on the wire (the transport reports it sent), or
before the bus waits for anything but the inter-frame gap: the listener's work (publishing)
never delays the next frame. Events that a step did not carry out (it sent nothing), and
with a transport that does not report its requests every event, go after the step.
"""

import math
from typing import Callable

from drive_bridge.bus.deadman import Deadman
from drive_bridge.bus.jobs import JobQueue
from drive_bridge.bus.link import LinkHealth
from drive_bridge.bus.outbox import EventOutbox
from drive_bridge.bus.polling import PollScheduler
from drive_bridge.bus.runner import TransactionRunner
from drive_bridge.bus.work import JobRunner
from drive_bridge.errors import LinkDown

CHOICE_LEAD_S = 0.0005  # the next frame is chosen this long before the gap ends (its build)
MIN_WAIT_S = 1e-6  # a shorter wait is none (below any timer's resolution)
LINK_DOWN_WAIT_S = 0.001  # the shortest wait while the link is down


class BusScheduler:
    """Choose and run the next piece of bus work; see the module docstring."""

    def __init__(self, link: LinkHealth, runner: TransactionRunner, jobs: JobQueue,
                 work: JobRunner, polls: PollScheduler, deadman: Deadman,
                 outbox: EventOutbox, clock: Callable[[], float]):
        self.link = link
        self.runner = runner
        self.jobs = jobs
        self.work = work
        self.polls = polls
        self.deadman = deadman
        self.outbox = outbox
        self.clock = clock

    def run_once(self) -> float:
        """Do the next piece of bus work; return how long to wait before the next one."""
        now = self.clock()
        if not self.link.up:
            wait_s = self.link.wait_s(now)
            if wait_s > 0 or not self.link.try_open():
                self._answer_jobs_while_down()
                self.outbox.deliver()
                return max(self.link.wait_s(self.clock()), LINK_DOWN_WAIT_S)
        # What goes next is chosen just before it can go, so that a command that comes in
        # the gap goes before the poll step that was next (the rest of the gap is slept in
        # the transaction). The events wait for the next request to leave.
        choose_in_s = self.runner.gap_left_s(now) - CHOICE_LEAD_S
        if choose_in_s > MIN_WAIT_S:
            return choose_in_s
        self.jobs.expire(now)
        self.deadman.check(now)
        emitted = self.outbox.emitted
        wait_s = self._run_next(now)
        # Also events that a step did not carry out (it sent nothing, or failed before).
        if wait_s > 0 or not self.runner.reports_request_sent or \
                self.outbox.delivered < emitted:
            self.outbox.deliver()
            if wait_s > 0:  # the wait started before the delivery
                wait_s = max(0.0, wait_s - (self.clock() - now))
        return wait_s

    def run_step(self, max_wait_s: float = math.inf) -> float:
        """Do the next piece of bus work, then sleep what it asks (at most ``max_wait_s``)."""
        wait_s = self.run_once()
        if wait_s > 0:
            self.runner.sleep(min(wait_s, max_wait_s))
        return wait_s

    def recover(self, reason: str) -> None:
        """After an internal error: drop the cycle in progress and take the link down."""
        try:
            self.polls.abandon()
            self.link.lost(reason)
        except Exception:  # noqa: B902 - the bus thread must never die
            pass
        self.outbox.deliver()

    def _run_next(self, now: float) -> float:
        """Run a job or a poll step; else return how long until a poll is due."""
        job = self.jobs.pop()
        if job is not None:
            self.work.run(job)
            return 0.0
        try:
            return self.polls.run_next(now)
        except LinkDown as error:
            self.link.lost(str(error))
            return 0.0

    def _answer_jobs_while_down(self) -> None:
        """While the link is down nothing can be sent: answer every waiting job now."""
        while True:
            job = self.jobs.pop()
            if job is None:
                return
            self.work.run_while_down(job)
