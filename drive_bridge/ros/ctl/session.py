"""
The bridge node as ``drive_bridge_ctl`` finds it in the ROS graph, with bounded waits.

Every wait spins the command's own node, so discovery and answers are taken as they come,
and ends early when SIGINT or SIGTERM came (:class:`Interrupted`). The node must appear
within ``--timeout``; once it is there, a service or topic of it that is not in the graph
within :data:`GRACE_S` more does not exist (its entities are discovered together with it),
and one that is there gets ``--timeout`` to match the command's own client or publisher.
"""

import os
import threading
import time
from typing import Callable, Dict, Iterable, List, Optional, Tuple

from drive_bridge.ros.ctl.values import BadInput, BRIDGE_NODE, Refused
from drive_bridge.ros.naming import COMMANDS_NODE_SUFFIX
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node, NodeNameNonExistentError
from rclpy.task import Future

GRACE_S = 2.0
SPIN_STEP_S = 0.05
Bridge = Tuple[str, str]  # a bridge node: (namespace, name)


class Interrupted(Exception):
    """SIGINT or SIGTERM came while waiting; the message says what may have happened."""


class BridgeSession:
    """The command's node, the bridge node it talks to, and the waits between them."""

    def __init__(self, node: Node, namespace: str, name: str, timeout_s: float,
                 stop: threading.Event, chosen: bool = True):
        self.node = node
        self.namespace = namespace
        self.name = name
        self.full_name = f'{namespace.rstrip("/")}/{name}'
        # False: neither --node nor --namespace was given, so a full name (/line1/feeder/start)
        # may say which bridge node is meant (see take_owner_of).
        self.chosen = chosen
        self.timeout_s = timeout_s
        self.stop = stop
        self._seen_at = 0.0
        self._executor = SingleThreadedExecutor(context=node.context)
        self._executor.add_node(node)

    def close(self) -> None:
        """Let go of the executor (the caller destroys the node)."""
        self._executor.shutdown(timeout_sec=1.0)

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Spin until ``predicate`` holds or ``timeout_s`` passed; return the predicate."""
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if self.stop.is_set():
                raise Interrupted()
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return bool(predicate())
            self._executor.spin_once(timeout_sec=min(SPIN_STEP_S, remaining))
        return True

    def find_node(self) -> None:
        """Wait up to ``--timeout`` for the bridge node; raise BadInput if it is not there."""
        if self._seen_at:
            return
        if not self.spin_until(self._node_present, self.timeout_s):
            raise self._no_node()
        self._seen_at = time.monotonic()

    def _no_node(self) -> BadInput:
        others = [_full(space, name) for space, name in self.bridges()]
        domain = os.environ.get('ROS_DOMAIN_ID') or '0'
        hint = f'ROS_DOMAIN_ID {domain} has {", ".join(others)}: choose with --node' \
            if others else f'is the bridge running, in ROS_DOMAIN_ID {domain} and this ' \
            'namespace?'
        return BadInput(f'no node {self.full_name} within {self.timeout_s:g} s ({hint})')

    def bridges(self) -> List[Bridge]:
        """Return (namespace, name) of every bridge node in the graph, sorted."""
        return sorted((space, name) for name, space in
                      self.node.get_node_names_and_namespaces() if name == BRIDGE_NODE)

    def take_owner_of(self, full_name: str, names: Callable[[Bridge], Iterable[str]],
                      what: str) -> None:
        """
        Make the bridge node that has ``full_name`` the session's node, if none was chosen.

        Without ``--node`` or ``--namespace``, a full name (``/line1/feeder/start``) says
        which bridge node is meant: ``names((namespace, name))`` lists what a bridge node has
        (its services, say). Bridge nodes are waited for as :meth:`find_node` waits; if none
        of them has ``full_name`` GRACE_S after the first appeared, the default node's own
        check follows when it is there, else BadInput names what they have (``what``).
        """
        if self.chosen:
            return
        first_seen: List[float] = []

        def owner() -> List[Bridge]:
            bridges = self.bridges()
            if bridges and not first_seen:
                first_seen.append(time.monotonic())
            if not self._seen_at and (self.namespace, self.name) in bridges:
                self._seen_at = time.monotonic()  # the default node: find_node's wait is over
            return [bridge for bridge in bridges if full_name in names(bridge)]

        def settled() -> bool:
            return bool(owner()) or bool(first_seen) and \
                time.monotonic() >= first_seen[0] + GRACE_S
        self.spin_until(settled, self.timeout_s)
        found = owner()
        if found:
            if found[0] != (self.namespace, self.name):
                self._seen_at = 0.0  # another node: find_node finds it (at once)
            self.namespace, self.name = found[0]
            self.full_name = _full(*found[0])
            return
        if not first_seen:
            raise self._no_node()
        if self._seen_at:
            return  # the default node is there: its own check names what it has
        offered = [f'{_full(*bridge)}: {self.listing(sorted(names(bridge)))}'
                   for bridge in self.bridges()]
        raise BadInput(f'no bridge node has {full_name} ({what} of {"; ".join(offered)})')

    def _node_present(self) -> bool:
        return (self.name, self.namespace) in self.node.get_node_names_and_namespaces()

    def wait_for(self, ready: Callable[[], bool], listed: Callable[[], bool]) -> bool:
        """
        Find the node, then wait for ``ready`` (an entity of the node matched to ours).

        An entity that is not even ``listed`` in the node's graph GRACE_S after the node
        appeared does not exist (False); one that is listed gets ``--timeout`` to match.
        """
        self.find_node()
        grace_s = max(0.0, self._seen_at + GRACE_S - time.monotonic())
        self.spin_until(lambda: ready() or listed(), grace_s)
        return ready() or (listed() and self.spin_until(ready, self.timeout_s))

    def answer(self, future: Future, what: str, hint: str = '') -> object:
        """Return the result of ``future``; raise Refused if none within ``--timeout``."""
        if not self.spin_until(future.done, self.timeout_s):
            raise Refused(f'no answer from {what} within {self.timeout_s:g} s{hint}')
        return future.result()

    # -- the bridge node's graph ---------------------------------------------------------
    # ``bridge``: (namespace, name) of a bridge node; the session's node if not given.
    def services(self, bridge: Optional[Bridge] = None) -> Dict[str, List[str]]:
        """Return service -> types of the bridge node ({} if it is gone)."""
        return self._query(self.node.get_service_names_and_types_by_node, bridge)

    def publications(self, bridge: Optional[Bridge] = None) -> Dict[str, List[str]]:
        """Return topic -> types the bridge node publishes."""
        return self._query(self.node.get_publisher_names_and_types_by_node, bridge)

    def subscriptions(self, bridge: Optional[Bridge] = None) -> Dict[str, List[str]]:
        """Return topic -> types the bridge's commands node subscribes to (speed references)."""
        return self._query(self.node.get_subscriber_names_and_types_by_node, bridge,
                           COMMANDS_NODE_SUFFIX)

    @property
    def commands_name(self) -> str:
        """Return the name of the bridge's commands node (its command subscriptions)."""
        return self.name + COMMANDS_NODE_SUFFIX

    def _query(self, query, bridge: Optional[Bridge], suffix: str = '') -> Dict[str, List[str]]:
        """Ask ``query`` about ``bridge`` (the session's node if None), its name + ``suffix``."""
        space, name = bridge or (self.namespace, self.name)
        try:
            return dict(query(name + suffix, space))
        except NodeNameNonExistentError:
            return {}

    def relative(self, names: List[str], suffix: str) -> List[str]:
        """Return the names ending in ``suffix``, relative to the namespace, without it."""
        prefix = self.namespace.rstrip('/') + '/'
        return sorted(name[len(prefix):len(name) - len(suffix)] for name in names
                      if name.startswith(prefix) and name.endswith(suffix))

    def devices(self) -> List[str]:
        """Return the device names of the bridge node (from its ``<name>/state`` topics)."""
        return self.relative(list(self.publications()), '/state')

    def listing(self, names: List[str]) -> str:
        """Return names for a message: ``a, b`` or ``none``."""
        return ', '.join(names) if names else 'none'


def _full(namespace: str, name: str) -> str:
    """Return a node's full name (/line1/drive_bridge)."""
    return f'{namespace.rstrip("/")}/{name}'
