"""
What drive_bridge keeps in a bag's ``metadata.yaml`` (rosbag2's ``custom_data``, text only).

``drive_bridge_record`` writes it and ``drive_bridge_plot`` reads it; a bag from
``ros2 bag record`` has none, and the plot does without. Key
``drive_bridge.speed_reference_at_start``: JSON, reference topic -> the bridge's
``<device>.speed_reference`` parameter [%] as the recording began.
"""

import json
import math
from typing import Dict, Mapping

REFERENCE_AT_START = 'drive_bridge.speed_reference_at_start'


def encode_references(references: Mapping[str, float]) -> str:
    """Return the custom data value of reference topic -> percent."""
    return json.dumps(dict(references), sort_keys=True)


def decode_references(custom_data: Mapping[str, object]) -> Dict[str, float]:
    """Return reference topic -> percent from a bag's custom data; {} if absent or malformed."""
    try:
        found = json.loads(custom_data.get(REFERENCE_AT_START, '{}'))
    except (TypeError, ValueError):
        return {}
    if not isinstance(found, dict):
        return {}
    return {topic: float(percent) for topic, percent in found.items()
            if isinstance(topic, str) and topic.endswith('/speed_reference')
            and _is_number(percent)}


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and \
        math.isfinite(value)
