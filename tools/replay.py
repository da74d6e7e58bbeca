"""Replaying benchmark bags over DDS and collecting outputs (demo, latency benchmark, tests).

:class:`BagSource` streams a bag's raw (CDR) camera messages in header-stamp order, with their
original stamps, plus its ground truth; :class:`Replayer` publishes them (raw, no re-encoding);
:class:`Collector` records every ``PointCloud2`` output per input stamp with its receipt time;
:func:`replay` drives both, either in lock-step (each depth image is sent once the output for
the previous one arrived: every frame is processed, as offline) or at a fixed rate (open loop:
what a live camera does). Colour and depth send times are jittered.

A camera that loses colour images is imitated by withholding every ``drop_color_every``-th
colour image, or all of them (``no_color``: the colour topic is not even advertised);
:func:`color_dropped_depth` names the depth images whose colour partner was withheld, so that a
benchmark can report them apart from the bag's own unpaired images.

Run as ``python -m tools.replay BAG`` it publishes a bag to a node that is already running
(``endeff_node --ros-args -r __ns:=/camera``), as a camera driver would, at a fixed rate:
``--help`` lists the options. To play a recording as it was recorded (every topic, with
``/clock``), ``endeff play`` is the user's command (:mod:`endeff_ros.bag.play`,
docs/output.md); this module is the benchmarks' driver (header-stamp order, jitter,
lock-step).
"""

from __future__ import annotations

import argparse
import heapq
import itertools
import struct
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from endeff_ros.bag.play import spin_for, spin_until
from endeff_ros.bag.reader import BagReader, ReaderOptions
from endeff_ros.ros import convert

# spin_for and spin_until live in the package, where ``endeff play`` (the user-facing player:
# every topic with its clock) shares them; tools.dds_run imports them from here.

KINDS = ('camera_info', 'color', 'depth')  # also the send priority at equal stamps
TOPICS = {'color': 'color/image_raw', 'depth': 'depth/image_raw',
          'camera_info': 'depth/camera_info'}


def positive_int(text: str) -> int:
    """argparse type of ``--drop-color-every``: a whole number of at least 1."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        msg = f'expected a whole number of at least 1, got {text!r}'
        raise argparse.ArgumentTypeError(msg)
    return value


def cdr_stamp(raw: bytes) -> int:
    """``header.stamp`` in ns of a CDR-serialised message whose first field is a Header."""
    order = '<' if raw[1] & 1 else '>'
    sec, nanosec = struct.unpack_from(f'{order}iI', raw, 4)
    return sec * 1_000_000_000 + nanosec


def restamp(raw: bytes, stamp_ns: int) -> bytes:
    """Copy of a CDR message (Header first) with ``header.stamp`` set to ``stamp_ns``."""
    order = '<' if raw[1] & 1 else '>'
    out = bytearray(raw)
    struct.pack_into(f'{order}iI', out, 4, *divmod(int(stamp_ns), 1_000_000_000))
    return bytes(out)


@dataclass(frozen=True)
class RawMessage:
    """One camera message of a bag: input kind, header stamp, serialised bytes."""

    kind: str
    stamp_ns: int
    raw: bytes


class BagSource:
    """A benchmark bag opened for replay (topics chosen as ``endeff eval`` chooses them)."""

    def __init__(self, path: str | Path, options: ReaderOptions | None = None) -> None:
        self.path = Path(path)
        self.bag = BagReader(self.path, options)
        self.bag.open()
        sel = self.bag.selection
        assert sel is not None
        self.name = self.bag.name
        self.topics = {'color': sel.color, 'depth': sel.depth, 'camera_info': sel.info}
        self.gt_topic = sel.gt

    def close(self) -> None:
        self.bag.close()

    def __enter__(self) -> BagSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _raw(self, topics: list[str]) -> Iterator[tuple[Any, bytes]]:
        conns = [c for c in self.bag.reader.connections if c.topic in topics]
        for conn, _, raw in self.bag.reader.messages(connections=conns):
            yield conn, bytes(raw)

    def ground_truth(self) -> dict[int, np.ndarray]:
        """Depth stamp -> (N, 3) ground-truth positions (finite rows only)."""
        out: dict[int, np.ndarray] = {}
        if not self.gt_topic:
            return out
        for conn, raw in self._raw([self.gt_topic]):
            msg = self.bag.reader.deserialize(raw, conn.msgtype)
            pos = convert.xyz(convert.cloud_to_array(msg))
            out[convert.stamp_to_ns(msg.header.stamp)] = pos[np.all(np.isfinite(pos), axis=1)]
        return out

    def depth_stamps(self) -> list[int]:
        """Header stamps of all depth images, sorted."""
        return sorted(cdr_stamp(raw) for _, raw in self._raw([self.topics['depth']]))

    def looped(self, loops: int) -> Iterator[RawMessage]:
        """:meth:`messages` ``loops`` times, later passes re-stamped to keep time increasing."""
        stamps = self.depth_stamps() if loops > 1 else [0]
        period = int(np.median(np.diff(stamps))) if len(stamps) > 1 else 0
        span = stamps[-1] - stamps[0] + period
        for loop in range(loops):
            for msg in self.messages():
                if loop == 0:
                    yield msg
                else:
                    stamp = msg.stamp_ns + loop * span
                    yield RawMessage(msg.kind, stamp, restamp(msg.raw, stamp))

    def messages(self, *, reorder_window_s: float = 1.0) -> Iterator[RawMessage]:
        """Camera messages in header-stamp order (camera info, colour, depth at equal stamps)."""
        kind_of = {topic: kind for kind, topic in self.topics.items()}
        window = round(reorder_window_s * 1e9)
        heap: list[tuple[int, int, int, RawMessage]] = []
        counter = itertools.count()
        newest = None
        for conn, raw in self._raw(list(self.topics.values())):
            kind = kind_of[conn.topic]
            item = RawMessage(kind, cdr_stamp(raw), raw)
            heapq.heappush(heap, (item.stamp_ns, KINDS.index(kind), next(counter), item))
            newest = item.stamp_ns if newest is None else max(newest, item.stamp_ns)
            while heap and newest - heap[0][0] > window:
                yield heapq.heappop(heap)[3]
        while heap:
            yield heapq.heappop(heap)[3]


def jittered(messages: Iterator[RawMessage], jitter_s: float,
             seed: int = 0) -> Iterator[tuple[int, RawMessage]]:
    """(send key ns, message): images delayed by up to ``jitter_s``, re-ordered by send key."""
    rng = np.random.default_rng(seed)
    jitter_ns = round(jitter_s * 1e9)
    heap: list[tuple[int, int, RawMessage]] = []
    counter = itertools.count()
    for msg in messages:
        delay = int(rng.integers(0, jitter_ns + 1)) if msg.kind != 'camera_info' else 0
        heapq.heappush(heap, (msg.stamp_ns + delay, next(counter), msg))
        while heap and heap[0][0] <= msg.stamp_ns:  # later messages have later keys
            key, _, m = heapq.heappop(heap)
            yield key, m
    while heap:
        key, _, m = heapq.heappop(heap)
        yield key, m


class Replayer:
    """Raw publishers of the camera inputs ``kinds`` under ``namespace`` (reliable QoS); an
    input left out is not advertised at all (``no_color``: a camera without colour)."""

    def __init__(self, node: Any, namespace: str = '/camera',
                 kinds: tuple[str, ...] = KINDS) -> None:
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import CameraInfo, Image

        unknown = set(kinds) - set(TOPICS)
        if unknown or 'depth' not in kinds:
            msg = f'replayer inputs must include depth and be among {KINDS}, got {kinds}'
            raise ValueError(msg)
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        ns = namespace.rstrip('/')
        self.pubs = {kind: node.create_publisher(CameraInfo if kind == 'camera_info' else Image,
                                                 f'{ns}/{TOPICS[kind]}', qos)
                     for kind in KINDS if kind in kinds}
        self.sent: dict[int, int] = {}  # depth stamp -> perf_counter_ns at publish

    def matched(self, depth_subscribers: int = 1) -> bool:
        """Every input has a subscriber; depth has at least ``depth_subscribers``."""
        return (all(p.get_subscription_count() > 0 for p in self.pubs.values()) and
                self.pubs['depth'].get_subscription_count() >= depth_subscribers)

    def publish(self, msg: RawMessage) -> None:
        if msg.kind == 'depth':
            self.sent[msg.stamp_ns] = time.perf_counter_ns()
        self.pubs[msg.kind].publish(msg.raw)


@dataclass
class Output:
    """One received cloud: receipt time (perf_counter ns), frame_id and points."""

    receipt_ns: int
    frame_id: str
    points: np.ndarray


@dataclass
class Collector:
    """Subscribes to ``PointCloud2`` outputs (name -> topic) and records them per stamp."""

    node: Any
    topics: dict[str, str]
    markers_topic: str | None = None
    clouds: dict[str, dict[int, Output]] = field(default_factory=dict)
    duplicates: dict[str, int] = field(default_factory=dict)
    markers: dict[int, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import PointCloud2
        from visualization_msgs.msg import MarkerArray

        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        for name, topic in self.topics.items():
            self.clouds[name] = {}
            self.duplicates[name] = 0
            self.node.create_subscription(PointCloud2, topic,
                                          lambda m, n=name: self._on_cloud(n, m), qos)
        if self.markers_topic:
            self.node.create_subscription(MarkerArray, self.markers_topic, self._on_markers,
                                          qos)

    def _on_cloud(self, name: str, msg: Any) -> None:
        now = time.perf_counter_ns()
        stamp = convert.stamp_to_ns(msg.header.stamp)
        if stamp in self.clouds[name]:
            self.duplicates[name] += 1
            return
        self.clouds[name][stamp] = Output(now, msg.header.frame_id, convert.cloud_to_array(msg))

    def _on_markers(self, msg: Any) -> None:
        if msg.markers:
            self.markers[convert.stamp_to_ns(msg.markers[0].header.stamp)] = msg

    def matched(self) -> bool:
        """Every output topic has a publisher."""
        return all(self.node.count_publishers(t) > 0 for t in self.topics.values())


@dataclass
class ReplayStats:
    """What a replay sent and how long it took."""

    depth_sent: list[int] = field(default_factory=list)
    color_sent: list[int] = field(default_factory=list)
    color_dropped: list[int] = field(default_factory=list)  # colour stamps withheld on purpose
    messages: int = 0
    waited_out: int = 0  # lock-step: outputs that never came within the timeout
    seconds: float = 0.0


def replay(executor: Any, source: BagSource, replayer: Replayer, *,
           collector: Collector | None = None, wait_on: str = 'node',
           rate_hz: float | None = None, jitter_s: float = 0.008,
           frame_timeout_s: float = 10.0, max_frames: int | None = None,
           loops: int = 1, seed: int = 0, drop_color_every: int | None = None,
           no_color: bool = False) -> ReplayStats:
    """Publish ``source`` through ``replayer``.

    Lock-step (``rate_hz=None``): before each depth image, wait (up to ``frame_timeout_s``)
    for ``collector``'s ``wait_on`` output of the previous one. Fixed rate: message times
    follow the header stamps, scaled so that depth images come at ``rate_hz``. ``loops`` > 1
    replays the bag again and again with shifted stamps (longer benchmarks).
    ``drop_color_every=N`` withholds the N-th, 2N-th, ... colour image of the stream (a camera
    losing 1 colour image in N); ``no_color`` withholds all of them. Withheld images keep
    their place in the timing (nothing is sent instead) and are listed in
    ``stats.color_dropped``.
    """
    if drop_color_every is not None and drop_color_every < 1:
        msg = f'drop_color_every must be at least 1 (colour images), got {drop_color_every}'
        raise ValueError(msg)
    stats = ReplayStats()
    colors = 0  # colour images of the stream so far, withheld ones included
    t_start = time.monotonic()
    scale = None
    if rate_hz is not None:
        stamps = source.depth_stamps()
        period = float(np.median(np.diff(stamps))) if len(stamps) > 1 else 1e9 / rate_hz
        scale = (1e9 / rate_hz) / period
    t0 = key0 = None
    for key, msg in jittered(source.looped(loops), jitter_s, seed):
        if msg.kind == 'depth':
            if max_frames is not None and len(stats.depth_sent) >= max_frames:
                break
            if scale is None and stats.depth_sent and collector is not None:
                prev = stats.depth_sent[-1]
                if not spin_until(executor, lambda p=prev: p in collector.clouds[wait_on],
                                  frame_timeout_s):
                    stats.waited_out += 1
        if scale is not None:
            if t0 is None:
                t0, key0 = time.monotonic(), key
            spin_for(executor, t0 + (key - key0) * scale / 1e9 - time.monotonic())
        elif msg.kind != 'camera_info':
            spin_for(executor, float(np.random.default_rng(key).uniform(0, jitter_s)))
        if msg.kind == 'color':
            colors += 1
            if no_color or (drop_color_every and colors % drop_color_every == 0):
                stats.color_dropped.append(msg.stamp_ns)
                continue
        replayer.publish(msg)
        stats.messages += 1
        if msg.kind == 'depth':
            stats.depth_sent.append(msg.stamp_ns)
        elif msg.kind == 'color':
            stats.color_sent.append(msg.stamp_ns)
        executor.spin_once(timeout_sec=0)
    stats.seconds = time.monotonic() - t_start
    return stats


def unpaired_depth(depth_stamps: list[int], color_stamps: list[int],
                   slop_ns: int) -> set[int]:
    """Depth stamps with no colour stamp within ``slop_ns``: frames the approximate-time
    synchroniser cannot complete (the synthetic bags drop some colour images on purpose)."""
    color = np.sort(np.asarray(color_stamps, dtype=np.int64))
    depth = np.asarray(depth_stamps, dtype=np.int64)
    if color.size == 0:
        return {int(s) for s in depth}
    i = np.searchsorted(color, depth)
    before, after = color[np.maximum(i - 1, 0)], color[np.minimum(i, color.size - 1)]
    gap = np.minimum(np.abs(depth - before), np.abs(depth - after))
    return {int(s) for s in depth[gap > slop_ns]}


def color_dropped_depth(depth_stamps: list[int], color_sent: list[int],
                        color_dropped: list[int], slop_ns: int) -> set[int]:
    """Depth stamps that had a colour partner within ``slop_ns`` in the bag but none among the
    colour images actually sent: the frames whose colour the replay withheld (a depth image
    the bag itself left unpaired is not one of them)."""
    return (unpaired_depth(depth_stamps, color_sent, slop_ns)
            - unpaired_depth(depth_stamps, [*color_sent, *color_dropped], slop_ns))


def latency_summary(sent: dict[int, int], outputs: dict[int, Output], stamps: list[int],
                    unpaired: set[int] = frozenset(),
                    color_dropped: set[int] = frozenset()) -> dict[str, Any]:
    """Delivered count, dropped frames and end-to-end latency percentiles (ms) of one output.

    Frames in ``unpaired`` (inputs that cannot be synchronised) without an output are counted
    as ``unpaired_inputs``, not as ``dropped_frames``. Frames in ``color_dropped`` (their
    colour image was withheld, :func:`color_dropped_depth`) are accounted apart, under
    ``color_dropped``: sent, outputs, ``dropped_frames`` (no output) and their own latency
    percentiles. The top-level percentiles cover every output, so that runs with and without
    colour losses compare as a whole.
    """
    missing = [s for s in stamps if s not in outputs and s not in color_dropped]
    lost_unpaired = sum(s in unpaired for s in missing)
    out: dict[str, Any] = {'frames_sent': len(stamps), 'outputs': 0,
                           'dropped_frames': len(missing) - lost_unpaired,
                           'unpaired_inputs': lost_unpaired}
    out.update(_summary(sent, outputs, stamps))
    lost = _summary(sent, outputs, [s for s in stamps if s in color_dropped])
    out['color_dropped'] = {'frames_sent': lost['frames_sent'], 'outputs': lost['outputs'],
                            'dropped_frames': lost['frames_sent'] - lost['outputs'], **lost}
    return out


def _summary(sent: dict[int, int], outputs: dict[int, Output],
             stamps: list[int]) -> dict[str, Any]:
    """Frames sent, outputs and latency percentiles (ms; none without outputs) of ``stamps``."""
    lat = np.array([(outputs[s].receipt_ns - sent[s]) / 1e6 for s in stamps if s in outputs],
                   dtype=np.float64)
    out: dict[str, Any] = {'frames_sent': len(stamps), 'outputs': int(lat.size)}
    if lat.size:
        p50, p95, p99 = np.percentile(lat, [50, 95, 99])
        out.update(latency_ms_p50=round(float(p50), 3), latency_ms_p95=round(float(p95), 3),
                   latency_ms_p99=round(float(p99), 3), latency_ms_max=round(float(lat.max()), 3))
    return out


def main(argv: list[str] | None = None) -> int:
    """``python -m tools.replay BAG``: publish a bag's camera messages to a running node."""
    import signal
    import sys

    from endeff_ros.bag.errors import BagError
    from endeff_ros.cli_common import Terminated, raise_terminated

    parser = argparse.ArgumentParser(
        prog='python -m tools.replay',
        description='Publish the camera messages of a benchmark bag (colour, depth, camera '
                    'info; raw, original stamps) under NAMESPACE at a fixed rate, as a camera '
                    'driver would, for a node that is already running, e.g. `endeff_node '
                    '--ros-args -r __ns:=/camera`. Ctrl-C stops.')
    parser.add_argument('bag', metavar='BAG', help='benchmark bag (directory, .mcap or .db3)')
    parser.add_argument('--namespace', default='/camera',
                        help='namespace of the published topics (default /camera)')
    parser.add_argument('--rate', type=float, default=30.0,
                        help='depth images per second (default 30)')
    parser.add_argument('--loops', type=positive_int, default=1,
                        help='replay the bag this many times, re-stamped (default 1)')
    parser.add_argument('--max-frames', type=positive_int, default=None, metavar='N',
                        help='stop after N depth images')
    parser.add_argument('--wait', type=float, default=10.0, metavar='S',
                        help='seconds to wait for a subscriber of every input (default 10)')
    color = parser.add_mutually_exclusive_group()
    color.add_argument('--drop-color-every', type=positive_int, default=None, metavar='N',
                       help='withhold every N-th colour image (a camera losing colour)')
    color.add_argument('--no-color', action='store_true',
                       help='no colour at all (the colour topic is not advertised)')
    args = parser.parse_args(argv)
    if not args.rate > 0:
        parser.error(f'argument --rate: must be above 0, got {args.rate}')
    try:
        source = BagSource(args.bag)
    except BagError as err:
        print(f'tools.replay: {err}', file=sys.stderr)
        return 2
    previous = signal.signal(signal.SIGTERM, raise_terminated)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    rclpy.init()
    node = rclpy.create_node('endeff_replay')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        with source:
            kinds = tuple(k for k in KINDS if not (args.no_color and k == 'color'))
            replayer = Replayer(node, args.namespace, kinds)
            if not spin_until(executor, replayer.matched, args.wait):
                print(f'tools.replay: warning: no subscriber of every input under '
                      f'{args.namespace} after {args.wait:g} s; publishing anyway',
                      file=sys.stderr)
            stats = replay(executor, source, replayer, rate_hz=args.rate, loops=args.loops,
                           max_frames=args.max_frames, drop_color_every=args.drop_color_every,
                           no_color=args.no_color)
        print(f'{source.name}: {len(stats.depth_sent)} depth images ({stats.messages} '
              f'messages) published under {args.namespace} in {stats.seconds:.1f} s')
        return 0
    except KeyboardInterrupt as err:
        print('tools.replay: interrupted', file=sys.stderr)
        return 143 if isinstance(err, Terminated) else 130
    finally:
        signal.signal(signal.SIGTERM, previous)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    raise SystemExit(main())
