"""Transaction statistics of one device, as /diagnostics shows them."""

from collections import Counter
from dataclasses import dataclass, field
from typing import Dict

from drive_bridge.errors import FAILURE_KINDS, TransportError


@dataclass
class DeviceStats:
    """Transaction statistics of one device; round-trip times in seconds."""

    transactions: int = 0
    errors: Counter = field(default_factory=Counter)
    retries: int = 0
    slow_replies: int = 0
    refused_writes: int = 0  # writes the monitor-only guard stopped before the wire
    late_replies: int = 0  # whole frames naming this device discarded as late (never taken)
    discarded_bytes: int = 0  # bytes discarded in its transactions that were no whole frame
    last_error: str = ''
    rtt_last_s: float = 0.0
    rtt_avg_s: float = 0.0
    rtt_max_s: float = 0.0

    def record_ok(self, rtt_s: float, slow: bool = False) -> None:
        """Count a transaction that got a valid reply (``slow``: later than the bus's limit)."""
        self.transactions += 1
        self.slow_replies += slow
        self.rtt_last_s = rtt_s
        self.rtt_max_s = max(self.rtt_max_s, rtt_s)
        weight = 0.1 if self.rtt_avg_s else 1.0
        self.rtt_avg_s += (rtt_s - self.rtt_avg_s) * weight

    def record_error(self, error: TransportError) -> None:
        """Count a failed transaction by the kind of failure."""
        self.transactions += 1
        self.errors[error.kind] += 1
        self.last_error = str(error)

    def as_dict(self) -> Dict[str, str]:
        """Return the statistics as text key/values for /diagnostics."""
        values = {
            'transactions': str(self.transactions),
            'errors': str(sum(self.errors.values())),
            'retries': str(self.retries),
            'slow_replies': str(self.slow_replies),
            'late_replies': str(self.late_replies),
            'discarded_bytes': str(self.discarded_bytes),
            'last_error': self.last_error,
            'rtt_last_ms': f'{self.rtt_last_s * 1000:.1f}',
            'rtt_avg_ms': f'{self.rtt_avg_s * 1000:.1f}',
            'rtt_max_ms': f'{self.rtt_max_s * 1000:.1f}',
        }
        for kind in FAILURE_KINDS:
            values[f'errors_{kind}'] = str(self.errors.get(kind, 0))
        if self.refused_writes:
            values['refused_writes'] = str(self.refused_writes)
        return values
