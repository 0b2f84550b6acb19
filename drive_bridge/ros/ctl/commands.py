"""
What ``drive_bridge_ctl`` does through the bridge node: services, topics, lifecycle.

Each function prints its result on stdout and returns the exit status, or raises a
:class:`~drive_bridge.ros.ctl.values.CtlError` with one line. A Trigger call is sent once
and never repeated; a lifecycle transition goes by label, never by id (ros2/rclpy#1209).
"""

import importlib
import math
from typing import Any, List, Optional

from drive_bridge.ros.ctl.session import Bridge, BridgeSession, Interrupted
from drive_bridge.ros.ctl.values import BadInput, message_text, Refused, resolve
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetAvailableTransitions, GetState
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float32, String
from std_srvs.srv import Trigger

TRIGGER = 'std_srvs/srv/Trigger'
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
TRANSITIONS = ('configure', 'activate', 'deactivate', 'cleanup', 'shutdown')
HIDDEN_TOPICS = ('/rosout', '/parameter_events')


def call(session: BridgeSession, service_name: str) -> int:
    """Call a Trigger service of the bridge once; exit status 0 on success, 1 if refused."""
    service = resolve(service_name, session.namespace, is_service=True)
    if service_name.startswith('/'):
        session.take_owner_of(service, _triggers(session), 'the Trigger services')
    client = session.node.create_client(Trigger, service)
    if not session.wait_for(client.service_is_ready,
                            lambda: TRIGGER in session.services().get(service, ())):
        services = session.services()
        if service in services:
            raise BadInput(f'{service} is a {services[service][0]} service, not a Trigger: '
                           'see the param and lifecycle commands')
        triggers = session.relative([name for name, types in services.items()
                                     if TRIGGER in types], '')
        hint = session.listing(triggers) if triggers else \
            'none: is it configured? see: lifecycle get'
        raise BadInput(f'{session.full_name} has no service {service} (its Trigger services: '
                       f'{hint}){_without_node_name(session, service, triggers)}')
    future = client.call_async(Trigger.Request())
    unknown = 'it may have been executed; look at the device state before calling again'
    try:
        response = session.answer(future, service, f': {unknown} (not repeated)')
    except Interrupted:
        raise Interrupted(f'{service} was called without an answer yet: {unknown}') from None
    print(f'success: {"true" if response.success else "false"}')
    print(f'message: {response.message}', flush=True)
    return 0 if response.success else 1


def _triggers(session: BridgeSession):
    """Return a lister of a bridge node's Trigger services (full names)."""
    def triggers(bridge: Bridge) -> List[str]:
        return [service for service, types in session.services(bridge).items()
                if TRIGGER in types]
    return triggers


def _topics(session: BridgeSession, suffix: str = '', subscribed: bool = False):
    """Return a lister of a bridge node's published (or subscribed) topics ending in suffix."""
    def topics(bridge: Bridge) -> List[str]:
        # The bridge's commands node takes the speed references.
        found = session.subscriptions(bridge) if subscribed else session.publications(bridge)
        return [topic for topic in found if topic.endswith(suffix) and topic not in HIDDEN_TOPICS]
    return topics


def _without_node_name(session: BridgeSession, service: str, triggers: List[str]) -> str:
    """Return a hint for a service named under the node's name (/drive_bridge/feeder/start)."""
    inside = service[len(session.full_name) + 1:] \
        if service.startswith(session.full_name + '/') else ''
    if inside not in triggers:
        return ''
    meant = resolve(inside, session.namespace, is_service=True)
    return f': service names do not include the node name, did you mean {meant}?'


def reference(session: BridgeSession, device: str, percent: float,
              rate_hz: Optional[float]) -> int:
    """Publish a speed reference once (delivered to the node), or at ``rate_hz`` until a signal."""
    topic = resolve(f'{device}/speed_reference', session.namespace)
    if device.startswith('/'):
        session.take_owner_of(topic, _topics(session, '/speed_reference', subscribed=True),
                              'the speed reference topics')
    publisher = session.node.create_publisher(Float32, topic, 10)

    def listed() -> bool:
        return _by_bridge(session, session.node.get_subscriptions_info_by_topic(topic),
                          session.commands_name)

    def connected() -> bool:
        readers = session.node.get_subscriptions_info_by_topic(topic)
        return _by_bridge(session, readers, session.commands_name) and \
            publisher.get_subscription_count() >= len(readers)
    if not session.wait_for(connected, listed):
        drives = session.relative(list(session.subscriptions()), '/speed_reference')
        raise BadInput(f'{session.full_name} takes no speed reference on {topic} (its drives: '
                       f'{session.listing(drives)})')
    message = Float32(data=float(percent))
    if rate_hz is None:
        publisher.publish(message)
        if not publisher.wait_for_all_acked(Duration(seconds=session.timeout_s)):
            raise Refused(f'{percent:g} % on {topic} was not acknowledged by the node within '
                          f'{session.timeout_s:g} s')
        print(f'published {percent:g} % on {topic} (received by the node)', flush=True)
        return 0
    sent = [0]

    def tick() -> None:
        publisher.publish(message)
        sent[0] += 1
    tick()
    session.node.create_timer(1.0 / rate_hz, tick)
    print(f'publishing {percent:g} % on {topic} at {rate_hz:g} Hz until Ctrl-C', flush=True)
    try:
        session.spin_until(lambda: False, math.inf)
    except Interrupted:
        pass
    print(f'stopped after {sent[0]} messages: the drive keeps {percent:g} % unless '
          f'{device}.reference_timeout is set', flush=True)
    return 0


def state(session: BridgeSession, device: str) -> int:
    """Print the device's latched state."""
    topic = resolve(f'{device}/state', session.namespace)
    if device.startswith('/'):
        session.take_owner_of(topic, _topics(session, '/state'), 'the state topics')
    received: List[String] = []
    session.node.create_subscription(String, topic, received.append, LATCHED)
    if not session.wait_for(
            lambda: _by_bridge(session, session.node.get_publishers_info_by_topic(topic)),
            lambda: False):
        raise BadInput(f'{session.full_name} has no device {device!r} (its devices: '
                       f'{session.listing(session.devices())})')
    if not session.spin_until(lambda: bool(received), session.timeout_s):
        raise Refused(f'no state on {topic} within {session.timeout_s:g} s')
    print(received[-1].data, flush=True)
    return 0


def _by_bridge(session: BridgeSession, endpoints, name: str = '') -> bool:
    """Return whether one of the topic ``endpoints`` belongs to the bridge node (or ``name``)."""
    return any(info.node_name == (name or session.name) and
               info.node_namespace == session.namespace for info in endpoints)


def echo(session: BridgeSession, topic_name: str, count: Optional[int]) -> int:
    """Print the messages on a topic, ``count`` of them (each within --timeout) or until Ctrl-C."""
    topic = resolve(topic_name, session.namespace)
    if topic_name.startswith('/'):
        session.take_owner_of(topic, _topics(session), 'the topics')
    if not session.wait_for(lambda: bool(session.node.get_publishers_info_by_topic(topic)),
                            lambda: False):
        published = sorted(name for name in session.publications() if name not in HIDDEN_TOPICS)
        raise BadInput(f'no publisher of {topic} ({session.full_name} publishes '
                       f'{session.listing(published)})')
    infos = session.node.get_publishers_info_by_topic(topic)
    received: List[Any] = []
    session.node.create_subscription(_message_class(topic, infos[0].topic_type), topic,
                                     received.append, _qos_of(infos))
    printed = 0
    try:
        while count is None or printed < count:
            if not session.spin_until(lambda: bool(received),
                                      math.inf if count is None else session.timeout_s):
                raise Refused(f'no message on {topic} within {session.timeout_s:g} s')
            print(message_text(received.pop(0)), flush=True)
            printed += 1
    except Interrupted:
        pass
    return 0


def _message_class(topic: str, type_name: str) -> Any:
    package, _, name = type_name.partition('/msg/')
    try:
        return getattr(importlib.import_module(f'{package}.msg'), name)
    except (ImportError, AttributeError):
        raise BadInput(f'{topic}: its type {type_name} is not installed here') from None


def _qos_of(infos) -> QoSProfile:
    """Return a QoS that matches every publisher: transient local and reliable where all are."""
    latched = all(info.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
                  for info in infos)
    reliable = all(info.qos_profile.reliability == ReliabilityPolicy.RELIABLE for info in infos)
    return QoSProfile(
        depth=10,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT)


def check_transition(label: str) -> str:
    """Return a lifecycle transition label; refuse an id (ros2/rclpy#1209) or a typo."""
    if label.isdigit():
        raise BadInput(f'give the transition by its label ({", ".join(TRANSITIONS)}), not by '
                       'id')
    if label not in TRANSITIONS:
        raise BadInput(f'unknown transition {label!r}: use one of {", ".join(TRANSITIONS)}')
    return label


def lifecycle(session: BridgeSession, action: str, label: str = '') -> int:
    """``get`` the state, ``list`` the transitions possible now, or ``set`` one by label."""
    base = session.full_name
    get_state = session.node.create_client(GetState, f'{base}/get_state')
    available = session.node.create_client(GetAvailableTransitions,
                                           f'{base}/get_available_transitions')
    change = session.node.create_client(ChangeState, f'{base}/change_state')
    clients = (get_state, available, change)
    if not session.wait_for(lambda: all(client.service_is_ready() for client in clients),
                            lambda: f'{base}/change_state' in session.services()):
        raise BadInput(f'{base} offers no lifecycle services')

    def current() -> str:
        return session.answer(get_state.call_async(GetState.Request()),
                              f'{base}/get_state').current_state.label
    now = current()
    if action == 'get':
        print(now, flush=True)
        return 0
    answer = session.answer(available.call_async(GetAvailableTransitions.Request()),
                            f'{base}/get_available_transitions')
    labels = list(dict.fromkeys(item.transition.label
                                for item in answer.available_transitions))
    if action == 'list':
        print('\n'.join(labels), flush=True)
        return 0
    if label not in labels:
        raise Refused(f'cannot {label}: {base} is {now} (possible now: '
                      f'{session.listing(labels)}); nothing sent')
    result = session.answer(
        change.call_async(ChangeState.Request(transition=Transition(label=label))),
        f'{base}/change_state')
    if not result.success:
        raise Refused(f'{label} failed: {base} is {current()} (see its log)')
    print(f'{label}: done, {base} is {current()}', flush=True)
    return 0
