"""Read RGB-D frames and ground truth from rosbag2 bags (sqlite3 or mcap, compressed or not).

A bag is a rosbag2 directory (with ``metadata.yaml``) or a single ``.mcap`` / ``.db3`` file.
Messages are deserialised with ``rosbags`` (definitions embedded in the bag, the Jazzy typestore
as fallback), converted by :mod:`endeff_ros.ros.convert` (duck-typed, no rclpy) and synchronised
exactly as the node does: :class:`endeff_ros.sync.ApproximateTimeSynchronizer` over colour and
depth with camera info latched, messages fed in header-stamp order, slop 15 ms by default.

Topics default to the benchmark-bag contract (``/camera/color/image_raw``,
``/camera/depth/image_raw``, ``/camera/depth/camera_info``, ``/ground_truth/end_effectors``).
When a bag lacks them, common driver layouts are recognised (RealSense ``realsense2_camera``
aligned depth, Azure Kinect ``depth_to_rgb``) under any namespace, and the choice is stated in
:attr:`TopicSelection.preset` / :meth:`TopicSelection.describe`. Recordings made through
image_transport count too: where a raw image topic is absent, ``<topic>/compressed`` (colour)
and ``<topic>/compressedDepth`` or ``<topic>/compressed`` (depth) of type
``sensor_msgs/msg/CompressedImage`` stand for it, decoded by :mod:`endeff_ros.image_codecs`.

Ground truth is matched to a frame by exact equality of its ``header.stamp`` with the depth
image's (the contract). A depth image that finds no colour partner within the slop is still
yielded, with ``color=None`` (the tracker falls back to predicting without optical flow): the
synchroniser reports each message it drops (``on_drop``) and the reader yields those depth
images as it learns of them.

A bag cut short is read up to its last readable message (:mod:`endeff_ros.bag.salvage` when
the index is gone) with a warning naming what was lost; ``strict`` refuses it. Reading,
deserialising and decoding run on a background thread ahead of the caller (``prefetch``).
"""

from __future__ import annotations

import contextlib
import functools
import heapq
import itertools
import os
import queue
import sys
import threading
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from endeff_ros.core.errors import InputError
from endeff_ros.sync import ApproximateTimeSynchronizer

from .errors import BagError

if TYPE_CHECKING:
    import argparse
    from collections.abc import Callable, Iterable, Iterator

    import numpy.typing as npt

    from endeff_ros.core.types import RGBDFrame

IMAGE = 'sensor_msgs/msg/Image'
COMPRESSED = 'sensor_msgs/msg/CompressedImage'
CAMERA_INFO = 'sensor_msgs/msg/CameraInfo'
POINTCLOUD2 = 'sensor_msgs/msg/PointCloud2'

DEFAULT_COLOR = '/camera/color/image_raw'
DEFAULT_DEPTH = '/camera/depth/image_raw'
DEFAULT_INFO = '/camera/depth/camera_info'
DEFAULT_GT = '/ground_truth/end_effectors'

#: (preset name, colour suffix, depth suffix, camera-info suffix), tried in this order under
#: any namespace. The benchmark contract's own names (namespace ``/camera``) always come first.
PRESETS: tuple[tuple[str, str, str, str], ...] = (
    ('benchmark contract', '/color/image_raw', '/depth/image_raw', '/depth/camera_info'),
    ('RealSense (realsense2_camera, aligned depth)', '/color/image_raw',
     '/aligned_depth_to_color/image_raw', '/aligned_depth_to_color/camera_info'),
    ('Azure Kinect (depth_to_rgb)', '/rgb/image_raw', '/depth_to_rgb/image_raw',
     '/rgb/camera_info'),
)

BAG_SUFFIXES = ('.mcap', '.db3')

#: image_transport topics that stand for a raw image topic when it is absent, in this order.
COLOR_VARIANTS = ('', '/compressed')
DEPTH_VARIANTS = ('', '/compressedDepth', '/compressed')


@dataclass(frozen=True)
class ReaderOptions:
    """How to read a bag. ``None`` topics are taken from the contract or auto-detected."""

    color_topic: str | None = None
    depth_topic: str | None = None
    info_topic: str | None = None
    gt_topic: str | None = None
    slop_s: float = 0.015
    queue_size: int = 10
    reorder_window_s: float = 1.0
    #: Refuse truncated or corrupt bags instead of reading them up to the last good message.
    strict: bool = False
    #: Read, deserialise and decode on a background thread, overlapped with the caller's work
    #: on the frames (file reads, zstd, numpy copies and OpenCV decoding release the GIL).
    #: None: when this process may run on more than one CPU. Frames are the same either way.
    prefetch: bool | None = None


def add_reader_arguments(parser: argparse.ArgumentParser) -> None:
    """Topic and synchronisation options shared by ``endeff eval`` and ``endeff process``."""
    g = parser.add_argument_group('input topics (default: benchmark contract, else detected)')
    g.add_argument('--color-topic', help=f'colour image topic (default {DEFAULT_COLOR})')
    g.add_argument('--depth-topic', help=f'registered depth topic (default {DEFAULT_DEPTH})')
    g.add_argument('--info-topic', help=f'depth camera info topic (default {DEFAULT_INFO})')
    g.add_argument('--gt-topic', help=f'ground-truth PointCloud2 topic (default {DEFAULT_GT})')
    g.add_argument('--slop', type=float, default=0.015, metavar='S',
                   help='colour/depth synchronisation slop in seconds (default 0.015)')
    g.add_argument('--queue-size', type=int, default=10, metavar='N',
                   help='synchroniser queue size per input (default 10)')
    g.add_argument('--strict', action='store_true',
                   help='refuse truncated or corrupt bags (default: read them up to the last '
                        'readable message, with a warning naming what was lost)')


def options_from_args(args: argparse.Namespace) -> ReaderOptions:
    """:class:`ReaderOptions` from the parsed :func:`add_reader_arguments` options."""
    return ReaderOptions(color_topic=args.color_topic, depth_topic=args.depth_topic,
                         info_topic=args.info_topic, gt_topic=args.gt_topic,
                         slop_s=float(args.slop), queue_size=int(args.queue_size),
                         strict=bool(getattr(args, 'strict', False)))


@dataclass(frozen=True)
class TopicSelection:
    """The topics chosen for a bag and why (``preset``)."""

    color: str
    depth: str
    info: str
    gt: str | None
    preset: str

    def describe(self) -> str:
        """One line naming the topics and how they were chosen."""
        gt = self.gt or 'none'
        return (f'{self.preset}: colour {self.color}, depth {self.depth}, '
                f'camera info {self.info}, ground truth {gt}')


@dataclass
class ReadStats:
    """Counters of one pass over a bag.

    ``dropped`` counts messages per topic that were not used in a yielded frame: colour images
    without a depth partner, depth images that came before any camera info or out of order.
    ``colorless`` counts frames yielded with ``color=None`` (depth without a colour partner).
    """

    messages: dict[str, int] = field(default_factory=dict)
    frames: int = 0
    colorless: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    gt_messages: int = 0
    gt_matched: int = 0
    #: Topic -> (messages read, messages the bag's metadata lists) where fewer were read.
    lost: dict[str, tuple[int, int]] = field(default_factory=dict)
    #: Why reading stopped early (truncated or corrupt storage), else None.
    read_error: str | None = None

    @property
    def gt_unmatched(self) -> int:
        """Ground-truth messages whose stamp equals no yielded depth frame's stamp."""
        return self.gt_messages - self.gt_matched

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly form."""
        return {'messages': dict(self.messages), 'frames': self.frames,
                'colorless_frames': self.colorless, 'dropped': dict(self.dropped),
                'gt_messages': self.gt_messages, 'gt_matched': self.gt_matched,
                'gt_unmatched': self.gt_unmatched,
                'lost': {t: {'read': r, 'expected': e} for t, (r, e) in self.lost.items()},
                'read_error': self.read_error}


class BagRecord(NamedTuple):
    """One yielded frame: the frame, its ground truth (N, 3) or None, the depth's log time."""

    frame: RGBDFrame
    gt: npt.NDArray[np.float64] | None
    log_time_ns: int


def is_bag(path: Path) -> bool:
    """A rosbag2 directory (``metadata.yaml``) or a single ``.mcap`` / ``.db3`` file."""
    if path.is_dir():
        return (path / 'metadata.yaml').is_file()
    return path.suffix in BAG_SUFFIXES


def find_bags(paths: Iterable[str | Path]) -> list[Path]:
    """Expand arguments to bags: bags stay, other directories are searched recursively.

    Raises :class:`BagError` for a path that does not exist or a directory without bags.
    """
    out: list[Path] = []
    for arg in paths:
        path = Path(arg)
        if not path.exists():
            raise BagError(path, 'no such file or directory')
        if is_bag(path):
            out.append(path)
            continue
        if not path.is_dir():
            raise BagError(path, f'not a rosbag2 bag (expected a directory with metadata.yaml '
                                 f'or a {" or ".join(BAG_SUFFIXES)} file)')
        found = _search(path)
        if not found:
            raise BagError(path, 'directory contains no rosbag2 bags')
        out.extend(found)
    return out


def _search(root: Path) -> list[Path]:
    found: list[Path] = []
    for child in sorted(root.iterdir()):
        if child.name.startswith('.'):  # hidden: outputs being written (bag.outputs.partial_dir)
            continue
        if child.is_dir():
            found.extend([child] if is_bag(child) else _search(child))
        elif child.suffix in BAG_SUFFIXES:
            found.append(child)
    return found


def bag_name(path: Path) -> str:
    """Sequence name of a bag: its directory name, or the file name without suffix."""
    path = Path(path)
    if path.is_dir():
        return path.resolve().name
    if (path.parent / 'metadata.yaml').is_file():
        return path.parent.resolve().name
    return path.stem


@functools.cache
def typestore() -> Any:
    """The Jazzy typestore (built once per process: about 80 ms)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


class _LazyTypestore:
    """Stands for :func:`typestore` as ``AnyReader``'s fallback, which reads only its
    ``fielddefs`` and only for bags without message definitions: most bags carry them, and
    importing the Jazzy store costs about 0.1 s of CPU per run."""

    @property
    def fielddefs(self) -> Any:
        return typestore().fielddefs


def _pick(topics: dict[str, str | None], base: str, variants: tuple[str, ...]) -> str | None:
    """The first of ``base + variant`` in the bag (raw before compressed), or None."""
    for v in variants:
        if base + v in topics:
            return base + v
    return None


def select_topics(topics: dict[str, str | None], options: ReaderOptions,
                  bag: object = '') -> TopicSelection:
    """Choose colour, depth, camera info and ground-truth topics from ``topic -> msgtype``.

    Explicit options win; otherwise the contract's names, else the first complete
    :data:`PRESETS` layout under any namespace. Where a raw image topic is absent, its
    image_transport variants count as well (``.../compressed`` for colour,
    ``.../compressedDepth`` then ``.../compressed`` for depth). Raises :class:`BagError`
    naming what is missing.
    """
    explicit = (options.color_topic, options.depth_topic, options.info_topic)
    gt = options.gt_topic or DEFAULT_GT
    if options.gt_topic is None and gt not in topics:
        gt_topic: str | None = None
    else:
        gt_topic = gt
    color = _pick(topics, DEFAULT_COLOR, COLOR_VARIANTS)
    depth = _pick(topics, DEFAULT_DEPTH, DEPTH_VARIANTS)
    if all(explicit):
        sel = TopicSelection(*explicit, gt_topic, 'given topics')  # type: ignore[arg-type]
    elif any(explicit):
        want = (options.color_topic or color or DEFAULT_COLOR,
                options.depth_topic or depth or DEFAULT_DEPTH, options.info_topic or DEFAULT_INFO)
        sel = TopicSelection(*want, gt_topic, 'given topics (others: benchmark contract)')
    elif color and depth and DEFAULT_INFO in topics:
        sel = TopicSelection(color, depth, DEFAULT_INFO, gt_topic, 'benchmark contract')
    else:
        sel = _detect(topics, gt_topic, bag)
    _check_types(topics, sel, bag)
    return sel


def _detect(topics: dict[str, str | None], gt_topic: str | None, bag: object) -> TopicSelection:
    for name, c_sfx, d_sfx, i_sfx in PRESETS:
        for variant in DEPTH_VARIANTS:
            ending = d_sfx + variant
            prefixes = sorted(t[:-len(ending)] for t in topics if t.endswith(ending))
            for prefix in prefixes:
                color = _pick(topics, prefix + c_sfx, COLOR_VARIANTS)
                info = prefix + i_sfx
                if color and info in topics:
                    return TopicSelection(color, prefix + ending, info, gt_topic,
                                          f'detected {name} layout')
    images = sorted(t for t, typ in topics.items() if typ in (IMAGE, COMPRESSED, CAMERA_INFO))
    wanted = ', '.join(t for t in (DEFAULT_COLOR, DEFAULT_DEPTH, DEFAULT_INFO)
                       if t not in topics)
    problem = (f'missing topic(s) {wanted} (raw or compressed) and no RealSense or Azure '
               f'Kinect layout found; image/camera-info topics in the bag: '
               f'{", ".join(images) or "none"} (choose with --color-topic/--depth-topic/'
               f'--info-topic)')
    raise BagError(bag, problem)


def _check_types(topics: dict[str, str | None], sel: TopicSelection, bag: object) -> None:
    wants = [('colour', sel.color, (IMAGE, COMPRESSED)), ('depth', sel.depth, (IMAGE, COMPRESSED)),
             ('camera info', sel.info, (CAMERA_INFO,))]
    if sel.gt is not None:
        wants.append(('ground truth', sel.gt, (POINTCLOUD2,)))
    for role, topic, types in wants:
        if topic not in topics:
            variants = COLOR_VARIANTS if role == 'colour' else DEPTH_VARIANTS
            near = [topic + v for v in variants[1:] if topic + v in topics]
            hint = f'; the bag has {", ".join(near)}' if near else ''
            raise BagError(bag, f'missing {role} topic {topic} ({sel.preset}){hint}')
        have = topics[topic]
        if have not in types:
            raise BagError(bag, f'{role} topic {topic} has type {have}, expected '
                                f'{" or ".join(types)}')


class BagReader:
    """One bag, opened for reading; use as a context manager.

    >>> with BagReader(path) as bag:            # doctest: +SKIP
    ...     print(bag.selection.describe())
    ...     for frame, gt in bag.frames():
    ...         ...
    """

    def __init__(self, path: str | Path, options: ReaderOptions | None = None, *,
                 warn: Callable[[str], Any] | None = None) -> None:
        self.path = Path(path)
        self.name = bag_name(self.path)
        self.options = options or ReaderOptions()
        self.stats = ReadStats()
        self._reader: Any = None
        self.selection: TopicSelection | None = None
        self.topic_types: dict[str, str | None] = {}
        self.topic_counts: dict[str, int] = {}
        #: Set when the bag's index could not be read and messages are read one by one.
        self.salvaged = False
        self._gt_read = 0
        self._read_error: str | None = None
        self._warn = warn if warn is not None else self._print_warning

    def _print_warning(self, text: str) -> None:
        print(f'{self.path}: warning: {text}', file=sys.stderr, flush=True)

    # -- opening -------------------------------------------------------------------------------

    def __enter__(self) -> BagReader:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self) -> None:
        """Open the bag, choose topics and check their types (:class:`BagError` if unusable)."""
        from rosbags.highlevel import AnyReader

        source = resolve_bag(self.path)
        try:
            reader = AnyReader([source], default_typestore=_LazyTypestore())
            reader.open()
        except Exception as err:  # rosbags, sqlite3, mcap, yaml, zstd errors alike
            reader = self._salvage(source, err)
        self._reader = reader
        try:
            self.topic_types = {name: info.msgtype for name, info in reader.topics.items()}
            # A salvaged bag without metadata.yaml has no counts (None): nothing to compare.
            self.topic_counts = {name: int(info.msgcount) for name, info in
                                 reader.topics.items() if info.msgcount is not None}
            self.selection = select_topics(self.topic_types, self.options, self.path)
            if self.topic_counts.get(self.selection.info, 1) == 0:
                raise BagError(self.path, f'camera info topic {self.selection.info} has no '
                                          f'messages (no intrinsics)')
            if self.topic_counts.get(self.selection.depth, 1) == 0:
                raise BagError(self.path, f'depth topic {self.selection.depth} has no messages')
        except BaseException:
            self.close()
            raise

    def _salvage(self, source: Path, err: Exception) -> Any:
        """A message-by-message reader when the index is unreadable (a file cut short)."""
        from .salvage import SalvageReader

        if self.options.strict:
            raise BagError(self.path, f'cannot open bag: {_why(err)} (--strict: truncated or '
                                      f'corrupt bags are refused)') from err
        try:
            reader = SalvageReader(source, typestore())
        except Exception as err2:  # noqa: BLE001 - the original error says more
            raise BagError(self.path, f'cannot open bag: {_why(err)}') from err2
        self.salvaged = True
        self._warn(f'the index of the bag cannot be read ({_why(err)}); reading its messages one '
                   f'by one up to the last readable one')
        return reader

    def close(self) -> None:
        """Close the underlying reader (idempotent)."""
        if self._reader is not None:
            reader, self._reader = self._reader, None
            try:
                reader.close()
            except Exception:  # noqa: S110 - closing a broken bag must not mask the real error
                pass

    @property
    def reader(self) -> Any:
        """The open ``rosbags.highlevel.AnyReader``."""
        if self._reader is None:
            msg = f'{self.path}: bag is not open'
            raise RuntimeError(msg)
        return self._reader

    @property
    def depth_count(self) -> int:
        """Depth messages in the bag (an upper bound on yielded frames)."""
        assert self.selection is not None
        return self.topic_counts.get(self.selection.depth, 0)

    # -- reading -------------------------------------------------------------------------------

    def frames(self) -> Iterator[tuple[RGBDFrame, npt.NDArray[np.float64] | None]]:
        """Yield ``(frame, gt_positions or None)`` per synchronised frame, in stamp order."""
        with contextlib.closing(self.records()) as records:
            for rec in records:
                yield rec.frame, rec.gt

    def records(self, *, ground_truth: bool = True) -> Iterator[BagRecord]:
        """Yield a :class:`BagRecord` per frame; raises :class:`BagError` on bad data.

        ``ground_truth=False`` skips the ground-truth topic (one pass less over the file;
        ``gt`` is then always None). A bag cut short is read up to its last readable message
        and a warning names what was lost (:attr:`ReadStats.lost`), unless
        :attr:`ReaderOptions.strict`, which raises :class:`BagError` instead.
        """
        from endeff_ros.ros import convert

        sel = self.selection
        if sel is None:
            self.open()
            sel = self.selection
        assert sel is not None
        self.stats = stats = ReadStats()
        self._read_error = None
        gt = self._read_gt(sel) if sel.gt and ground_truth else {}
        stats.gt_messages = len(gt)
        conns = [c for c in self.reader.connections if c.topic in (sel.color, sel.depth,
                                                                     sel.info)]
        index = {sel.color: 0, sel.depth: 1, sel.info: 2}
        # Same header stamp: camera info first, so a frame uses the info stamped with it.
        priority = {sel.info: 0, sel.color: 1, sel.depth: 2}
        for topic in index:
            stats.messages[topic] = 0
            stats.dropped[topic] = 0
        # Depth images the synchroniser dropped (no colour partner, queue overflow, late) are
        # still frames: they are yielded colour-less, in stamp order with the emitted sets, as
        # soon as the synchroniser gives up on them, so memory stays bounded by its queue.
        gone: list[_Entry] = []

        def on_drop(i: int, _stamp: int, item: Any, _reason: str) -> None:
            if i == 1:
                gone.append(item)
            else:
                stats.dropped[sel.color] += 1

        sync = ApproximateTimeSynchronizer(3, self.options.queue_size,
                                           round(self.options.slop_s * 1e9), latched=(2,),
                                           on_drop=on_drop)
        last_info: Any = None
        last_yielded = -1

        def build(color: _Entry | None, depth: _Entry, info: Any) -> BagRecord | None:
            nonlocal last_yielded
            if depth.stamp <= last_yielded or info is None:
                stats.dropped[sel.depth] += 1
                return None
            try:
                for e in (depth, color):
                    if e is not None and e.error is not None:
                        raise e.error
                frame = convert.frame_from_messages(color.msg if color else None, depth.msg,
                                                    info, depth=depth.image,
                                                    color=color.image if color else None)
            except InputError as err:
                problem = f'frame at stamp {depth.stamp} ns (depth {sel.depth}): {err}'
                raise BagError(self.path, problem) from err
            positions = gt.get(depth.stamp)
            if positions is not None:
                stats.gt_matched += 1
            stats.frames += 1
            stats.colorless += color is None
            last_yielded = depth.stamp
            return BagRecord(frame, positions, depth.log_time)

        def emit(sets: list[tuple[Any, ...]]) -> Iterator[BagRecord]:
            partner = {id(depth): (color, info) for color, depth, info in sets}
            ready = sorted([*gone, *(depth for _, depth, _ in sets)], key=lambda e: e.stamp)
            gone.clear()
            for d in ready:
                color, info = partner.get(id(d), (None, last_info))
                rec = build(color, d, info)
                if rec is not None:
                    yield rec

        source = self._ordered(conns, priority)
        prefetch = self.options.prefetch
        if prefetch or (prefetch is None and cpus() > 1):
            source = self._prefetched(source, {sel.color: convert.any_color_to_array,
                                               sel.depth: convert.any_depth_to_array})
        # Closed explicitly, so that leaving early (close, exception) stops a reader thread at
        # once rather than whenever the generator is garbage-collected.
        with contextlib.closing(source):
            for entry in source:
                stats.messages[entry.topic] += 1
                i = index[entry.topic]
                if i == 2:
                    last_info = entry.msg
                yield from emit(sync.add(i, entry.stamp, entry if i < 2 else entry.msg))
        sync.flush()
        yield from emit([])
        if stats.messages[sel.info] == 0:
            raise BagError(self.path, f'no camera info on {sel.info} (no intrinsics)')
        read = dict(stats.messages)
        if sel.gt and ground_truth:
            read[sel.gt] = self._gt_read
        self._account_losses(read, sel)

    def _account_losses(self, read: dict[str, int], sel: TopicSelection) -> None:
        """Compare messages read with the bag's counts; warn (or raise when strict)."""
        stats = self.stats
        stats.read_error = self._read_error
        stats.lost = {t: (got, self.topic_counts[t]) for t, got in read.items()
                      if got < self.topic_counts.get(t, 0)}
        if not stats.lost and self._read_error is None:
            return
        parts = [f'{got} of {want} messages on {t}' for t, (got, want) in stats.lost.items()]
        if sel.depth not in stats.lost:
            parts.append(f'{read.get(sel.depth, 0)} depth images on {sel.depth}')
        detail = f' ({self._read_error})' if self._read_error else ''
        problem = (f'truncated or corrupt bag{detail}: read {"; ".join(parts)}; '
                   f'{stats.frames} frames yielded')
        if self.options.strict:
            raise BagError(self.path, f'{problem} (--strict)')
        self._warn(f'{problem}; the rest is lost (--strict refuses such bags)')

    def _read_gt(self, sel: TopicSelection) -> dict[int, npt.NDArray[np.float64]]:
        from endeff_ros.ros import convert

        out: dict[int, npt.NDArray[np.float64]] = {}
        conns = [c for c in self.reader.connections if c.topic == sel.gt]
        self._gt_read = 0
        for conn, _, raw in self.raw_messages(conns):
            self._gt_read += 1
            msg = self._deserialize(raw, conn)
            try:
                points = convert.cloud_to_array(msg)
                names = points.dtype.names or ()
                if not {'x', 'y', 'z'} <= set(names):
                    missing = sorted({'x', 'y', 'z'} - set(names))
                    msg_ = f'has no field(s) {", ".join(missing)}'
                    raise InputError(msg_)
                pos = convert.xyz(points)
            except InputError as err:
                stamp = convert.stamp_to_ns(msg.header.stamp)
                raise BagError(self.path, f'ground truth {sel.gt} at stamp {stamp} ns: '
                                          f'{err}') from err
            out[convert.stamp_to_ns(msg.header.stamp)] = pos[np.all(np.isfinite(pos), axis=1)]
        return out

    def raw_messages(self, conns: list[Any]) -> Iterator[tuple[Any, int, bytes]]:
        """Raw ``(connection, log time, data)`` of ``conns`` in the storage's order.

        A storage-level failure (truncated or corrupt file) ends the iteration; it is kept for
        the warning of :meth:`records` or, with ``strict``, raised as :class:`BagError`.
        """
        if not conns:
            return
        it = self.reader.messages(connections=conns)
        while True:
            try:
                item = next(it)
            except StopIteration:
                return
            except Exception as err:
                if self.options.strict:
                    raise BagError(self.path, f'cannot read messages (truncated or corrupt '
                                              f'file, --strict): {_why(err)}') from err
                self._read_error = self._read_error or _why(err)
                return
            yield item

    def _deserialize(self, raw: bytes, conn: Any) -> Any:
        try:
            return self.reader.deserialize(raw, conn.msgtype)
        except Exception as err:
            raise BagError(self.path, f'cannot decode a {conn.msgtype} message on {conn.topic} '
                                      f'(corrupt data?): {_why(err)}') from err

    def _prefetched(self, source: Iterator[_Entry], decoders: dict[str, Callable[[Any], Any]],
                    depth: int = 8) -> Iterator[_Entry]:
        """``source`` run on a daemon thread, images decoded there, at most ``depth`` ahead.

        Errors of the thread (BagError, storage errors) are raised here, in order; closing
        this generator (early exit, exception, interrupt) stops the thread and waits for it.
        """
        items: queue.Queue[Any] = queue.Queue(maxsize=depth)
        stop = threading.Event()

        def put(item: Any) -> bool:
            while not stop.is_set():
                try:
                    items.put(item, timeout=0.05)
                except queue.Full:
                    continue
                return True
            return False

        def work() -> None:
            try:
                for entry in source:
                    decode = decoders.get(entry.topic)
                    if decode is not None:
                        try:
                            entry.image = decode(entry.msg)
                        except InputError as err:
                            entry.error = err
                    if not put(entry):
                        return
                put(_END)
            except BaseException as err:  # noqa: BLE001 - handed to the consumer
                put(err)

        thread = threading.Thread(target=work, name=f'bag-reader {self.name}', daemon=True)
        thread.start()
        try:
            while True:
                item = items.get()
                if item is _END:
                    return
                if isinstance(item, BaseException):
                    raise item
                yield item
        finally:
            stop.set()
            thread.join()

    def _ordered(self, conns: list[Any], priority: dict[str, int]) -> Iterator[_Entry]:
        """Messages of ``conns`` deserialised and re-ordered by header stamp.

        Recording order (log time) may differ from ``header.stamp``; a heap holds messages
        until a message ``reorder_window_s`` newer (by header stamp) has been read.
        """
        from endeff_ros.ros import convert

        window = round(self.options.reorder_window_s * 1e9)
        heap: list[tuple[int, int, int, _Entry]] = []
        newest = None
        counter = itertools.count()
        for conn, log_time, raw in self.raw_messages(conns):
            msg = self._deserialize(raw, conn)
            stamp = convert.stamp_to_ns(msg.header.stamp)
            entry = _Entry(conn.topic, stamp, log_time, msg)
            heapq.heappush(heap, (stamp, priority[conn.topic], next(counter), entry))
            newest = stamp if newest is None else max(newest, stamp)
            while heap and newest - heap[0][0] > window:
                yield heapq.heappop(heap)[3]
        while heap:
            yield heapq.heappop(heap)[3]


@dataclass(eq=False)
class _Entry:
    topic: str
    stamp: int
    log_time: int
    msg: Any
    image: Any = None  # the image decoded ahead (reader thread), else None
    error: Exception | None = None  # why decoding ahead failed (raised when the frame is built)


_END = object()


def cpus() -> int:
    """CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def options_for_workers(options: ReaderOptions, workers: int) -> ReaderOptions:
    """``options`` for each of ``workers`` processes reading bags at once: a reader thread
    per worker only helps while cores are left over (an explicit ``prefetch`` is kept)."""
    if workers > 1 and options.prefetch is None:
        return replace(options, prefetch=workers < cpus())
    return options


def resolve_bag(path: Path) -> Path:
    """The path rosbags opens for ``path``: a bag directory, a storage file, or the only
    storage file of a directory without ``metadata.yaml`` (as :func:`find_bags` reads it)."""
    if not path.exists():
        raise BagError(path, 'no such file or directory')
    if is_bag(path):
        return path
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix in BAG_SUFFIXES and p.is_file())
        if len(files) == 1:
            return files[0]
        if files:
            raise BagError(path, f'directory without metadata.yaml holds {len(files)} storage '
                                 f'files ({", ".join(f.name for f in files)}): pass them one '
                                 f'by one or restore metadata.yaml (ros2 bag reindex)')
    raise BagError(path, 'not a rosbag2 bag (need a directory with metadata.yaml or a .mcap / '
                         '.db3 file)')


def _why(err: BaseException) -> str:
    text = str(err).strip() or repr(err)
    return f'{type(err).__name__}: {text}'


def read_frames(path: str | Path, options: ReaderOptions | None = None
                ) -> Iterator[tuple[RGBDFrame, npt.NDArray[np.float64] | None]]:
    """Convenience: open ``path`` and yield ``(frame, gt or None)`` for every frame."""
    with BagReader(path, options) as bag:
        yield from bag.frames()
