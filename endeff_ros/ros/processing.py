"""The node's reusable, ROS-free pieces: node parameter table, newest-set slot, statistics.

Kept out of ``node.py`` so that the node stays thin wiring and so that these can be tested and
reused (latency benchmark, demo) without DDS.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

import numpy as np

from endeff_ros.core.errors import ParameterError
from endeff_ros.core.params import EndeffParams

T = TypeVar('T')

RELIABILITIES = ('best_effort', 'reliable')
TRANSPORTS = ('raw', 'compressed', 'auto')


def _row(name: str, default: Any, doc: str, *, lo: float | None = None,
         hi: float | None = None, unit: str = '', runtime: bool = True) -> dict[str, Any]:
    return {'name': name, 'type': type(default).__name__, 'default': default, 'doc': doc,
            'symbol': '', 'unit': unit, 'lo': lo, 'hi': hi, 'runtime': runtime}


#: Node-only parameters, in the same row format as :func:`endeff_ros.core.params.describe`.
NODE_PARAMS: list[dict[str, Any]] = [
    _row('input_reliability', 'best_effort', "QoS reliability of the image and camera-info "
         "subscriptions: 'best_effort' (sensor data) or 'reliable'.", runtime=False),
    _row('output_reliability', 'reliable', "QoS reliability of the outputs: 'reliable' "
         "(matches both kinds of subscriber) or 'best_effort'.", runtime=False),
    _row('input_queue_depth', 5, 'History depth of the input subscriptions.', lo=1, hi=100,
         runtime=False),
    _row('image_transport', 'raw', "Image topics to subscribe to: 'raw' (color/image_raw, "
         "depth/image_raw), 'compressed' (image_transport's color/image_raw/compressed and "
         "depth/image_raw/compressedDepth) or 'auto' (raw, switching an image input to its "
         "compressed topic when only that one has publishers).", runtime=False),
    _row('use_color', True, 'Synchronise the colour image (needed by the optical-flow '
         'predict phase); false: depth and camera info only.', runtime=False),
    _row('sync_queue_size', 10, 'Approximate-time synchroniser: messages kept per input.',
         lo=1, hi=1000),
    _row('sync_slop', 0.015, 'Approximate-time synchroniser: largest stamp difference between '
         'colour and depth of one set.', unit='s', lo=0.0, hi=1.0),
    _row('color_timeout', 0.1, 'A depth image still without a colour partner after this '
         'long is processed without colour (as the offline bag reader does).', unit='s',
         lo=0.0, hi=10.0),
    _row('publish_debug_bands', False, 'Publish debug/bands: the foreground cloud coloured '
         'by sub-band.'),
    _row('publish_debug_image', False, 'Publish debug/image: the colour image with the '
         'end-effectors drawn on it.'),
    _row('marker_lifetime', 0.2, 'Lifetime of the end_effectors/markers.', unit='s', lo=0.0,
         hi=60.0),
    _row('diagnostics_period', 1.0, 'Period of the /diagnostics status.', unit='s', lo=0.1,
         hi=60.0),
    _row('log_period', 30.0, 'Period of the statistics summary in the log.', unit='s', lo=1.0,
         hi=3600.0),
    _row('time_jump_threshold', 1.0, 'Input stamps going back by more than this reset the '
         'tracker and the synchroniser (bag replay loops).', unit='s', lo=0.0, hi=3600.0),
]


def describe_text(row: dict[str, Any]) -> str:
    """Human-readable parameter description with paper symbol, unit and range."""
    text = row['doc']
    if row.get('symbol'):
        text += f' Paper symbol: {row["symbol"]}.'
    if row.get('unit'):
        text += f' Unit: {row["unit"]}.'
    if row.get('lo') is not None or row.get('hi') is not None:
        text += f' Range: [{row["lo"]}, {row["hi"]}].'
    return text


def updated_params(params: EndeffParams, changes: dict[str, Any]) -> EndeffParams:
    """``params`` with ``changes`` applied, validated (raises :class:`ParameterError`)."""
    known = set(params.to_dict())
    relevant = {k: v for k, v in changes.items() if k in known}
    if not relevant:
        return params
    return EndeffParams.from_dict({**params.to_dict(), **relevant})


def validate_node_changes(changes: dict[str, Any]) -> None:
    """Cross-checks of node-only parameters the descriptors cannot express."""
    for key in ('input_reliability', 'output_reliability'):
        if key in changes and changes[key] not in RELIABILITIES:
            msg = f'{key} must be one of {RELIABILITIES}, not {changes[key]!r}'
            raise ParameterError(msg)
    if 'image_transport' in changes and changes['image_transport'] not in TRANSPORTS:
        msg = f"image_transport must be one of {TRANSPORTS}, not {changes['image_transport']!r}"
        raise ParameterError(msg)


class LatestSlot(Generic[T]):
    """Holds only the newest item; putting over an unconsumed one counts it as skipped.

    This is what keeps the node's latency bounded: callbacks ``put`` synchronised sets, the
    worker ``take``\\ s the newest, and anything it was too slow for is dropped, never queued.
    """

    def __init__(self, cond: threading.Condition | None = None) -> None:
        self._cond = cond or threading.Condition()  # slots may share one (take_first)
        self._item: T | None = None
        self._closed = False
        self.skipped = 0
        self.put_count = 0

    def companion(self) -> LatestSlot[Any]:
        """A new slot sharing this one's condition, so :func:`take_first` can wait on both."""
        return LatestSlot(self._cond)

    def put(self, item: T) -> None:
        with self._cond:
            if self._item is not None:
                self.skipped += 1
            self._item = item
            self.put_count += 1
            self._cond.notify()

    def take(self, timeout: float | None = None) -> T | None:
        """The newest item (removing it), waiting up to ``timeout`` s; None if none/closed."""
        with self._cond:
            if self._item is None and not self._closed:
                self._cond.wait(timeout)
            item, self._item = self._item, None
            return item

    def clear(self) -> None:
        with self._cond:
            self._item = None

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    @property
    def closed(self) -> bool:
        return self._closed


def take_first(slots: list[LatestSlot[Any]], timeout: float | None = None,
               ) -> tuple[int, Any] | None:
    """``(index, item)`` of the first of ``slots`` (which share one condition) holding an
    item, taking it; waits up to ``timeout`` s when all are empty; None if none / closed."""
    cond = slots[0]._cond
    with cond:
        if all(s._item is None for s in slots) and not slots[0]._closed:
            cond.wait(timeout)
        for k, slot in enumerate(slots):
            if slot._item is not None:
                item, slot._item = slot._item, None
                return k, item
    return None


class Window:
    """The last ``size`` samples of a quantity, with percentiles."""

    def __init__(self, size: int = 300) -> None:
        self._values: deque[float] = deque(maxlen=size)

    def add(self, value: float) -> None:
        self._values.append(float(value))

    def __len__(self) -> int:
        return len(self._values)

    def summary(self) -> dict[str, float]:
        if not self._values:
            return {}
        a = np.asarray(self._values)
        p50, p95, p99 = np.percentile(a, [50, 95, 99])
        return {'mean': float(a.mean()), 'p50': float(p50), 'p95': float(p95),
                'p99': float(p99), 'max': float(a.max())}


@dataclass
class NodeStats:
    """Counters and timing windows the node reports on /diagnostics and in the log."""

    received: dict[str, int] = field(default_factory=lambda: {'color': 0, 'depth': 0,
                                                              'camera_info': 0})
    processed: int = 0
    prepared: int = 0  # sets whose Sections 3-4 ran early, while the colour image was awaited
    prepared_flow: int = 0  # sets whose optical flow ran early, while the depth was awaited
    #: colour images whose flow ran in the subscription callback, alongside the worker's early
    #: Sections 3-4 of their depth partner
    flow_alongside: int = 0
    colorless: int = 0
    quarantined: int = 0  # messages stamped far ahead of the stream, dropped
    duplicates: int = 0
    published_empty: int = 0
    bad_input: int = 0
    errors: int = 0
    resets: int = 0
    warnings: dict[str, int] = field(default_factory=dict)
    last_warning: str = ''
    processing_ms: Window = field(default_factory=Window)
    latency_ms: Window = field(default_factory=Window)
    age_ms: Window = field(default_factory=Window)
    started: float = field(default_factory=time.monotonic)

    def warn(self, kind: str, message: str) -> None:
        self.warnings[kind] = self.warnings.get(kind, 0) + 1
        self.last_warning = message

    def as_dict(self, *, dropped: dict[str, int], skipped: int, sets: int) -> dict[str, Any]:
        """Flat, JSON-friendly snapshot."""
        return {
            'received': dict(self.received), 'sets': sets, 'processed': self.processed,
            'prepared': self.prepared, 'prepared_flow': self.prepared_flow,
            'flow_alongside': self.flow_alongside,
            'colorless': self.colorless, 'duplicates': self.duplicates,
            'quarantined': self.quarantined,
            'skipped': skipped, 'dropped_unpaired': dict(dropped),
            'published_empty': self.published_empty, 'bad_input': self.bad_input,
            'errors': self.errors, 'resets': self.resets, 'warnings': dict(self.warnings),
            'processing_ms': self.processing_ms.summary(),
            'latency_ms': self.latency_ms.summary(), 'age_ms': self.age_ms.summary(),
            'uptime_s': time.monotonic() - self.started,
        }


def flatten(d: dict[str, Any], prefix: str = '') -> list[tuple[str, str]]:
    """Nested dict -> sorted (dotted key, text value) pairs for diagnostic KeyValues."""
    out: list[tuple[str, str]] = []
    for key, value in d.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            out.extend(flatten(value, name + '.'))
        elif isinstance(value, float):
            out.append((name, f'{value:.3f}'))
        else:
            out.append((name, str(value)))
    return out
