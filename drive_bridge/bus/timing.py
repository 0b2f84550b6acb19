"""The retry and timing policy of one bus (the ``bus`` settings, in seconds)."""

from dataclasses import dataclass


@dataclass
class BusTiming:
    """Retry and timing policy of one bus; times in seconds."""

    retries: int = 2
    offline_after: int = 3
    backoff_initial_s: float = 1.0
    backoff_max_s: float = 10.0
    frame_gap_s: float = 0.0
    command_deadline_s: float = 2.0  # a command not on the wire by then is dropped
    transaction_timeout_s: float = 0.5  # the link's timeout: the longest one transaction waits
    slow_reply_s: float = 0.0  # a valid reply slower than this counts as slow; 0 = off
