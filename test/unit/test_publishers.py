"""The device topics: what a reading publishes, and that nobody's topic costs nothing."""

from drive_bridge.devices.contracts import DeviceReading
import pytest

# rclpy is not in the pymodbus 3.6.9 venv (transport tiers only): skipped there.
publishers = pytest.importorskip('drive_bridge.ros.node.publishers',
                                 reason='ROS 2 (rclpy) from PyPI')


class FakePublisher:
    """A lifecycle publisher: the messages it sent, and how many subscriptions it has."""

    def __init__(self, msg_type):
        self.msg_type = msg_type
        self.subscriptions = 0
        self.sent = []

    def get_subscription_count(self):
        return self.subscriptions

    def publish(self, message):
        self.sent.append(message.data)


class FakeNode:
    """What DevicePublishers needs of the node: it creates lifecycle publishers."""

    def __init__(self):
        self.topics = {}

    def create_lifecycle_publisher(self, msg_type, topic, qos, event_callbacks=None):
        self.topics[topic] = FakePublisher(msg_type)
        return self.topics[topic]


FIELDS = frozenset({'motor_current', 'speed_feedback'})
READING = DeviceReading(state='running', status_word=0x0F07, motor_current_a=4.5,
                        speed_feedback_pct=40.0)


def sent(node):
    return {topic: publisher.sent for topic, publisher in node.topics.items()
            if publisher.sent}


def test_a_reading_goes_to_every_topic_a_subscription_listens_to():
    node = FakeNode()
    device = publishers.DevicePublishers(node, 'feeder', FIELDS)
    for publisher in node.topics.values():
        publisher.subscriptions = 1
    device.publish_reading(READING)
    assert sent(node) == {'feeder/state': ['running'], 'feeder/trip': [''],
                          'feeder/status_word': [0x0F07], 'feeder/trip_code': [0],
                          'feeder/motor_current': [4.5], 'feeder/speed_feedback': [40.0]}


def test_volatile_topics_nobody_listens_to_are_skipped_and_latched_ones_never_are():
    node = FakeNode()
    device = publishers.DevicePublishers(node, 'feeder', FIELDS)
    device.publish_reading(READING)
    # state and trip are latched: a later subscriber gets the last one, so they always go.
    assert sent(node) == {'feeder/state': ['running'], 'feeder/trip': ['']}
    node.topics['feeder/motor_current'].subscriptions = 1  # ros2 topic echo feeder/motor_current
    device.publish_reading(READING)
    assert sent(node) == {'feeder/state': ['running'], 'feeder/trip': [''],
                          'feeder/motor_current': [4.5]}


def test_activation_publishes_again_what_the_bus_told_last():
    node = FakeNode()
    device = publishers.DevicePublishers(node, 'feeder', FIELDS)
    device.republish()  # nothing told yet
    assert sent(node) == {'feeder/state': ['unknown']}
    device.publish_reading(READING)
    device.republish()  # the latched topics again, though unchanged
    assert sent(node) == {'feeder/state': ['unknown', 'running', 'running'],
                          'feeder/trip': ['', '']}
    device.publish_state('offline')
    device.republish()  # a state without a reading: never the reading before it
    assert sent(node)['feeder/state'][-2:] == ['offline', 'offline']
    assert sent(node)['feeder/trip'] == ['', '']


class DiagnosticsNode:
    """What DiagnosticsPublisher needs of the node: a publisher and a clock it counts."""

    def __init__(self):
        self.publisher = None
        self.clock_reads = 0

    def create_publisher(self, msg_type, topic, qos):
        assert topic == '/diagnostics'
        self.publisher = FakePublisher(msg_type)
        self.publisher.publish = self.publisher.sent.append
        return self.publisher

    def get_clock(self):
        self.clock_reads += 1
        from rclpy.clock import Clock
        return Clock()


def test_diagnostics_nobody_listens_to_are_not_even_built():
    node_diagnostics = pytest.importorskip('drive_bridge.ros.node.diagnostics_publisher')
    node = DiagnosticsNode()
    diagnostics = node_diagnostics.DiagnosticsPublisher(node)
    diagnostics.publish(None)
    assert node.publisher.sent == [] and node.clock_reads == 0  # no array was put together
    node.publisher.subscriptions = 1  # an aggregator, ros2 topic echo /diagnostics, a bag
    diagnostics.publish(None)
    assert len(node.publisher.sent) == 1 and node.clock_reads == 1
    assert node.publisher.sent[0].status == []  # no bus: an empty array, stamped
    assert node.publisher.sent[0].header.stamp.sec > 0
