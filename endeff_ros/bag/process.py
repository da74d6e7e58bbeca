"""``endeff process``: run the tracker over rosbag2 bags and write the results as new bags.

Each input bag is read with :class:`~endeff_ros.bag.reader.BagReader` (synchronised exactly as
the node does) and every frame goes through one :class:`~endeff_ros.core.tracker.Tracker`. The
output bag (``--storage mcap`` by default, or ``sqlite3``) holds

- ``/camera/end_effectors`` (``sensor_msgs/msg/PointCloud2``) from
  :func:`endeff_ros.ros.convert.tracks_to_cloud`, and
- ``/camera/end_effectors/markers`` (``visualization_msgs/msg/MarkerArray``) from
  :func:`endeff_ros.ros.convert.result_to_markers`,

built as rclpy messages (the node's builders), serialised with
``rclpy.serialization.serialize_message`` and written as raw CDR with ``rosbags``. Their header is
the input depth image's (stamp and frame id); their log time is the depth message's log time.
With ``--copy-input`` every input topic is copied as well (raw, same log times).

With one input, ``-o OUT`` is the output bag; with several, ``OUT`` is a directory and each
output is ``OUT/<bag name>``, one process per bag (``--jobs``, default: all cores). An existing
output is never overwritten without ``--force``, and even then only if it is a bag. Outputs are
written to a hidden sibling and renamed when complete. A bad bag gives an error naming the bag
and the problem; the other bags continue; the exit status is 1 if any bag failed.

rclpy is imported only when output messages are built (never by ``endeff eval``).
"""

from __future__ import annotations

import argparse
import heapq
import multiprocessing
import os
import shutil
import sys
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

from endeff_ros.cli_common import load_params_option
from endeff_ros.core.errors import EndeffError, InputError

from .errors import BagError
from .reader import BagReader, ReaderOptions, add_reader_arguments, bag_name, options_from_args

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from endeff_ros.core.params import EndeffParams

    TrackerFactory = Callable[[EndeffParams | None], Any]

OUTPUT_CLOUD = '/camera/end_effectors'
OUTPUT_MARKERS = '/camera/end_effectors/markers'
CLOUD_TYPE = 'sensor_msgs/msg/PointCloud2'
MARKERS_TYPE = 'visualization_msgs/msg/MarkerArray'


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``endeff process``."""
    parser.add_argument('inputs', nargs='+', metavar='IN_BAG',
                        help='input bags (directory with metadata.yaml, .mcap or .db3)')
    parser.add_argument('-o', '--output', required=True, metavar='OUT',
                        help='output bag (one input) or directory of output bags (several)')
    parser.add_argument('--force', action='store_true',
                        help='replace existing output bags')
    parser.add_argument('--params', metavar='YAML',
                        help='parameter file (ROS 2 parameter YAML or flat mapping)')
    parser.add_argument('--jobs', type=int, default=None, metavar='N',
                        help='bags processed in parallel (default: number of cores)')
    parser.add_argument('--copy-input', action='store_true',
                        help='also copy every input topic into the output bag')
    parser.add_argument('--storage', choices=('mcap', 'sqlite3'), default='mcap',
                        help='output storage (default mcap)')
    parser.add_argument('--marker-lifetime', type=float, default=0.2, metavar='S',
                        help='lifetime of the markers in seconds (default 0.2, as the node)')
    add_reader_arguments(parser)


@dataclass
class ProcessResult:
    """Outcome of one bag: frame count and timing, or the error."""

    input: str
    output: str
    frames: int = 0
    seconds: float = 0.0
    error: str | None = None
    empty_frames: int = 0
    topics: str = ''
    read_stats: dict[str, Any] = field(default_factory=dict)

    @property
    def fps(self) -> float:
        """Frames per second of the whole bag (reading, tracking, writing)."""
        return self.frames / self.seconds if self.seconds > 0 else 0.0


def output_paths(inputs: Sequence[str | Path], output: str | Path) -> list[Path]:
    """One output per input: ``output`` itself for one input, else ``output/<bag name>``.

    Raises :class:`BagError` if two inputs would write the same output.
    """
    out = Path(output)
    if len(inputs) == 1:
        return [out]
    paths = [out / bag_name(Path(i)) for i in inputs]
    seen: dict[Path, str] = {}
    for i, p in zip(inputs, paths, strict=True):
        if p in seen:
            raise BagError(i, f'same output {p} as {seen[p]} (rename one of the bags)')
        seen[p] = str(i)
    return paths


def _check_output(in_path: Path, out_path: Path, force: bool) -> None:
    if not out_path.exists() and not out_path.is_symlink():
        if in_path.resolve() == out_path.resolve():
            raise BagError(in_path, 'output is the input bag')
        return
    if not force:
        raise BagError(in_path, f'output {out_path} exists (use --force to replace it)')
    inp, outp = in_path.resolve(), out_path.resolve()
    if inp == outp or outp in inp.parents:
        raise BagError(in_path, f'output {out_path} is or contains the input bag: not replacing '
                                f'it')
    if out_path.is_dir() and not (out_path / 'metadata.yaml').is_file() and any(
            out_path.iterdir()):
        raise BagError(in_path, f'output {out_path} exists and is not a rosbag2 bag: not '
                                f'deleting it, even with --force')


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


def _typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


_EMPTY_ESTIMATE = SimpleNamespace(entities=[])


def process_bag(in_path: str | Path, out_path: str | Path, *,
                params: EndeffParams | None = None, options: ReaderOptions | None = None,
                storage: str = 'mcap', force: bool = False, copy_input: bool = False,
                marker_lifetime_s: float = 0.2, tracker_factory: TrackerFactory | None = None,
                progress: Callable[[int], None] | None = None) -> ProcessResult:
    """Track every frame of ``in_path`` and write ``out_path``; raises :class:`BagError`.

    ``tracker_factory(params)`` (default :class:`Tracker`) builds the tracker; ``progress(n)``
    is called with the number of frames done since the previous call.
    """
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import StoragePlugin

    from endeff_ros.ros import convert

    if tracker_factory is None:
        from endeff_ros.core.tracker import Tracker

        tracker_factory = Tracker
    in_path, out_path = Path(in_path), Path(out_path)
    _check_output(in_path, out_path, force)
    plugin = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}[storage]
    result = ProcessResult(str(in_path), str(out_path))
    t0 = time.perf_counter()
    # Written inside a hidden sibling directory (so that the storage file gets the final
    # name), then moved into place.
    tmp_dir = out_path.parent / f'.{out_path.name}.partial-{os.getpid()}'
    tmp = tmp_dir / out_path.name
    _remove(tmp_dir)
    tmp_dir.mkdir(parents=True)
    ts = _typestore()
    try:
        with BagReader(in_path, options) as bag:
            assert bag.selection is not None
            result.topics = bag.selection.describe()
            tracker = tracker_factory(params)
            writer = Writer(tmp, version=9, storage_plugin=plugin)
            with writer:
                c_cloud = writer.add_connection(OUTPUT_CLOUD, CLOUD_TYPE, typestore=ts)
                c_mark = writer.add_connection(OUTPUT_MARKERS, MARKERS_TYPE, typestore=ts)
                buffered: list[tuple[int, int, Any, bytes]] = []
                for n, rec in enumerate(bag.records()):
                    try:
                        res = tracker.update(rec.frame)
                    except InputError:  # as the node: publish an empty result
                        res = SimpleNamespace(tracks=[], estimate=_EMPTY_ESTIMATE)
                        result.empty_frames += 1
                    header = convert.make_header(rec.frame.stamp_ns, rec.frame.frame_id)
                    cloud = convert.serialize(convert.tracks_to_cloud(header, res.tracks))
                    markers = convert.serialize(
                        convert.result_to_markers(header, res, marker_lifetime_s))
                    if copy_input:
                        buffered.append((rec.log_time_ns, 2 * n, c_cloud, cloud))
                        buffered.append((rec.log_time_ns, 2 * n + 1, c_mark, markers))
                    else:
                        writer.write(c_cloud, rec.log_time_ns, cloud)
                        writer.write(c_mark, rec.log_time_ns, markers)
                    result.frames += 1
                    if progress is not None:
                        progress(1)
                if copy_input:
                    _copy_merged(bag, writer, buffered)
            result.read_stats = bag.stats.to_dict()
        if result.frames == 0:
            raise BagError(in_path, 'no synchronised frames (colour, depth and camera info '
                                    'never lined up)')
        if out_path.exists() or out_path.is_symlink():
            _remove(out_path)
        tmp.rename(out_path)
    finally:
        _remove(tmp_dir)
    result.seconds = time.perf_counter() - t0
    return result


def _copy_merged(bag: BagReader, writer: Any, outputs: list[tuple[int, int, Any, bytes]]
                 ) -> None:
    """Write every input message (raw) merged by log time with the buffered outputs."""
    from rosbags.interfaces import MessageDefinitionFormat

    ts = _typestore()
    mapping: dict[int, Any] = {}
    out_keys: dict[tuple[str, str], Any] = {}
    for conn in bag.reader.connections:
        if conn.topic in (OUTPUT_CLOUD, OUTPUT_MARKERS):
            continue  # an already processed bag: its old results are replaced
        key = (conn.topic, conn.msgtype)
        if key not in out_keys:
            ext = getattr(conn, 'ext', None)
            qos = list(getattr(ext, 'offered_qos_profiles', []) or [])
            try:
                if conn.msgdef.format != MessageDefinitionFormat.NONE:
                    rihs01 = conn.digest or bag.reader.typestore.hash_rihs01(conn.msgtype)
                    out_keys[key] = writer.add_connection(conn.topic, conn.msgtype,
                                                          msgdef=conn.msgdef.data,
                                                          rihs01=rihs01,
                                                          offered_qos_profiles=qos)
                else:
                    store = ts if conn.msgtype in ts.fielddefs else bag.reader.typestore
                    out_keys[key] = writer.add_connection(conn.topic, conn.msgtype,
                                                          typestore=store,
                                                          offered_qos_profiles=qos)
            except Exception as err:
                raise BagError(bag.path, f'cannot copy topic {conn.topic} ({conn.msgtype}): '
                                         f'{type(err).__name__}: {err}') from err
        mapping[id(conn)] = out_keys[key]
    conns = [c for c in bag.reader.connections if id(c) in mapping]
    inputs = ((log, -1, mapping[id(conn)], raw) for conn, log, raw in bag._messages(conns))
    for log, _, conn, raw in heapq.merge(inputs, iter(outputs), key=lambda r: (r[0], r[1])):
        writer.write(conn, log, raw)


# --------------------------------------------------------------------------------------------
# Several bags, several processes
# --------------------------------------------------------------------------------------------

_COUNTER: Any = None


def _init_worker(counter: Any) -> None:
    global _COUNTER
    _COUNTER = counter


def _count(n: int) -> None:
    if _COUNTER is not None:
        with _COUNTER.get_lock():
            _COUNTER.value += n


def _job(job: tuple[Any, ...]) -> ProcessResult:
    """Process one bag; never raises (the error is in the result, naming the bag)."""
    in_path, out_path, kwargs = job
    try:
        return process_bag(in_path, out_path, progress=_count, **kwargs)
    except BagError as err:
        return ProcessResult(str(in_path), str(out_path), error=str(err))
    except EndeffError as err:
        return ProcessResult(str(in_path), str(out_path), error=f'{in_path}: {err}')
    except Exception as err:
        tb = traceback.format_exc(limit=6)
        return ProcessResult(str(in_path), str(out_path),
                             error=f'{in_path}: {type(err).__name__}: {err}\n{tb}')


class Progress:
    """A one-line progress bar on stderr (frames, frames/s, ETA), drawn only on a TTY."""

    def __init__(self, total: int, enabled: bool | None = None) -> None:
        self.total = max(total, 0)
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self.t0 = time.perf_counter()
        self.done = 0
        self._last = 0.0

    def update(self, done: int, *, force: bool = False) -> None:
        """Redraw with ``done`` frames finished (at most 10 times a second)."""
        self.done = done
        now = time.perf_counter()
        if not self.enabled or (not force and now - self._last < 0.1):
            return
        self._last = now
        sys.stderr.write('\r' + self.line(now) + '\033[K')
        sys.stderr.flush()

    def line(self, now: float | None = None) -> str:
        """The text of the bar."""
        elapsed = (now or time.perf_counter()) - self.t0
        rate = self.done / elapsed if elapsed > 0 else 0.0
        total = max(self.total, self.done)
        frac = self.done / total if total else 0.0
        bar = '#' * int(24 * frac) + '.' * (24 - int(24 * frac))
        eta = (total - self.done) / rate if rate > 0 else float('nan')
        eta_s = f'{int(eta // 60)}:{int(eta % 60):02d}' if eta == eta else '?'
        return f'[{bar}] {self.done}/{total} frames  {rate:5.1f} frames/s  ETA {eta_s}'

    def close(self) -> None:
        """Finish the line."""
        if self.enabled:
            self.update(self.done, force=True)
            sys.stderr.write('\n')
            sys.stderr.flush()


def _count_frames(paths: Sequence[Path], options: ReaderOptions) -> int:
    total = 0
    for p in paths:
        try:
            with BagReader(p, options) as bag:
                total += bag.depth_count
        except BagError:
            pass  # reported when the bag is processed
    return total


def process_bags(inputs: Sequence[str | Path], output: str | Path, *, jobs: int | None = None,
                 show_progress: bool | None = None, **kwargs: Any) -> list[ProcessResult]:
    """Process several bags, one process per bag (``jobs`` at a time); never raises BagError.

    ``kwargs`` go to :func:`process_bag` (``params``, ``options``, ``storage``, ``force``,
    ``copy_input``, ``marker_lifetime_s``, ``tracker_factory``; the factory must be picklable).
    """
    try:
        outs = output_paths(inputs, output)
    except BagError as err:
        return [ProcessResult(str(i), '', error=str(err)) for i in inputs]
    if len(inputs) > 1:
        Path(output).mkdir(parents=True, exist_ok=True)
    job_list = [(Path(i), o, kwargs) for i, o in zip(inputs, outs, strict=True)]
    enabled = sys.stderr.isatty() if show_progress is None else show_progress
    total = _count_frames([j[0] for j in job_list], kwargs.get('options') or ReaderOptions()) \
        if enabled else 0
    bar = Progress(total, enabled)
    workers = max(1, min(jobs or os.cpu_count() or 1, len(job_list)))
    if workers == 1:
        done = [0]

        def local(n: int) -> None:
            done[0] += n
            bar.update(done[0])

        results = []
        for in_path, out_path, kw in job_list:
            try:
                results.append(process_bag(in_path, out_path, progress=local, **kw))
            except BagError as err:
                results.append(ProcessResult(str(in_path), str(out_path), error=str(err)))
            except EndeffError as err:
                results.append(ProcessResult(str(in_path), str(out_path),
                                             error=f'{in_path}: {err}'))
        bar.close()
        return results
    ctx = multiprocessing.get_context()
    counter = ctx.Value('q', 0)
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                             initargs=(counter,)) as pool:
        futures: list[Future[ProcessResult]] = [pool.submit(_job, j) for j in job_list]
        pending = set(futures)
        while pending:
            _, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            bar.update(counter.value)
        bar.update(counter.value, force=True)
    bar.close()
    return [f.result() for f in futures]


def run(args: argparse.Namespace) -> int:
    """``endeff process``: 0 if every bag was processed, 1 if any failed, 2 on bad options."""
    params = load_params_option(args.params, 'endeff process')
    if args.jobs is not None and args.jobs < 1:
        print('endeff process: --jobs must be >= 1', file=sys.stderr)
        return 2
    results = process_bags(args.inputs, args.output, jobs=args.jobs, params=params,
                           options=options_from_args(args), storage=args.storage,
                           force=args.force, copy_input=args.copy_input,
                           marker_lifetime_s=args.marker_lifetime)
    failed = 0
    for r in results:
        if r.error:
            failed += 1
            print(f'endeff process: FAILED {r.error}', file=sys.stderr)
        else:
            print(f'{r.input}: {r.topics}', file=sys.stderr)
            extra = ''
            colorless = r.read_stats.get('colorless_frames', 0)
            if colorless:
                extra += f', {colorless} without colour'
            if r.empty_frames:
                extra += f', {r.empty_frames} rejected by the tracker'
            print(f'{r.input} -> {r.output}: {r.frames} frames in {r.seconds:.1f} s '
                  f'({r.fps:.1f} frames/s{extra})')
    return 1 if failed else 0
