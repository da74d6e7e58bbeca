"""``endeff process``: run the tracker over rosbag2 bags and write the results as new bags.

Each input bag is read with :class:`~endeff_ros.bag.reader.BagReader` (synchronised exactly as
the node does) and every frame goes through one :class:`~endeff_ros.core.tracker.Tracker`. The
output bag (``--storage mcap`` by default, or ``sqlite3``) holds

- ``/camera/end_effectors`` (``sensor_msgs/msg/PointCloud2``) from
  :func:`endeff_ros.ros.convert.tracks_to_cloud`, and, with ``--markers`` only,
- ``/camera/end_effectors/markers`` (``visualization_msgs/msg/MarkerArray``) from
  :func:`endeff_ros.ros.convert.result_to_markers` (building a dozen Python marker objects per
  frame costs about a fifth of the time the tracker takes, for a topic only RViz reads),

the cloud serialised by ``rosbags`` (:func:`cloud_cdr`, the same message as the node's
:func:`~endeff_ros.ros.convert.tracks_to_cloud`, checked by the tests), the markers built as
rclpy messages by the node's builder and serialised with ``rclpy``. Their header is the input
depth image's (stamp and frame id); their log time is the depth message's log time.
With ``--copy-input`` every input topic is copied as well (raw, same log times).

Inputs are expanded as ``endeff eval`` does (:func:`~endeff_ros.bag.reader.find_bags`: a folder
without ``metadata.yaml`` is searched for bags). With one bag, ``-o OUT`` is the output bag; with
several, ``OUT`` is a directory and each output is ``OUT/<bag name>``, one process per bag
(``--jobs``, default: all cores). Every output is checked before any bag is read
(:func:`~endeff_ros.bag.outputs.check_output_path`): an existing output is replaced only with
``--force`` and only if it is an earlier output bag. Outputs are written to a hidden sibling and
renamed when complete; an interrupted run (SIGINT, SIGTERM) removes what it had not finished, so
an output is either a complete bag or absent, and a run killed outright leaves a hidden
directory that the next run removes. A bad bag gives an error naming the bag and the problem;
the other bags continue; the exit status is 1 if any bag failed, 2 for unusable options or
outputs, 130/143 when interrupted.

rclpy is imported only for ``--markers`` (never by ``endeff eval``).
"""

from __future__ import annotations

import argparse
import functools
import heapq
import os
import sqlite3
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np

from endeff_ros.cli_common import Terminated, load_params_option, positive_int
from endeff_ros.core.errors import EndeffError, InputError

from . import progress as prog
from .errors import BagError
from .outputs import (
    WRITER,
    WRITER_KEY,
    OutputError,
    check_output_path,
    partial_dir,
    remove,
    replace_into_place,
    sweep_stale_partials,
    write_error,
)
from .reader import (
    BagReader,
    ReaderOptions,
    add_reader_arguments,
    bag_name,
    find_bags,
    options_for_workers,
    options_from_args,
    typestore,
)

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from endeff_ros.core.params import EndeffParams

    TrackerFactory = Callable[[EndeffParams | None], Any]

OUTPUT_CLOUD = '/camera/end_effectors'
OUTPUT_MARKERS = '/camera/end_effectors/markers'
OUTPUT_TOPICS = (OUTPUT_CLOUD, OUTPUT_MARKERS)
CLOUD_TYPE = 'sensor_msgs/msg/PointCloud2'
MARKERS_TYPE = 'visualization_msgs/msg/MarkerArray'


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``endeff process``."""
    parser.add_argument('inputs', nargs='+', metavar='IN_BAG',
                        help='input bags (directory with metadata.yaml, .mcap or .db3) or '
                             'directories searched for bags')
    parser.add_argument('-o', '--output', required=True, metavar='OUT',
                        help='output bag (one input) or directory of output bags (several)')
    parser.add_argument('--force', action='store_true',
                        help='replace existing output bags written by endeff process')
    parser.add_argument('--params', metavar='YAML',
                        help='parameter file (ROS 2 parameter YAML or flat mapping)')
    parser.add_argument('--jobs', type=positive_int, default=None, metavar='N',
                        help='bags processed in parallel (default: number of cores)')
    parser.add_argument('--copy-input', action='store_true',
                        help='also copy every input topic into the output bag')
    parser.add_argument('--storage', choices=('mcap', 'sqlite3'), default='mcap',
                        help='output storage (default mcap)')
    parser.add_argument('--markers', action='store_true',
                        help=f'also write {OUTPUT_MARKERS} (MarkerArray for RViz; off by '
                             f'default)')
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


def check_outputs(inputs: Sequence[str | Path], output: str | Path, *, force: bool = False
                  ) -> tuple[list[Path], list[str]]:
    """Output path per input and every problem with them (one line each), before any work."""
    try:
        outs = output_paths(inputs, output)
    except BagError as err:
        return [], [str(err)]
    problems = []
    if len(inputs) > 1:
        try:
            check_output_path(output, kind='dir')
        except OutputError as err:
            return outs, [f'output {err}']
    for i, o in zip(inputs, outs, strict=True):
        try:
            check_output_path(o, force=force, inputs=[i], own_topics=OUTPUT_TOPICS)
        except OutputError as err:
            problems.append(f'output {err}')
    return outs, problems


_EMPTY_ESTIMATE = SimpleNamespace(entities=[])

#: ROS 2 definitions of the output cloud's types (sensor_msgs, std_msgs, builtin_interfaces).
_CLOUD_MSGS = {
    'builtin_interfaces/msg/Time': 'int32 sec\nuint32 nanosec\n',
    'std_msgs/msg/Header': 'builtin_interfaces/Time stamp\nstring frame_id\n',
    'sensor_msgs/msg/PointField': (
        'uint8 INT8=1\nuint8 UINT8=2\nuint8 INT16=3\nuint8 UINT16=4\nuint8 INT32=5\n'
        'uint8 UINT32=6\nuint8 FLOAT32=7\nuint8 FLOAT64=8\n'
        'string name\nuint32 offset\nuint8 datatype\nuint32 count\n'),
    CLOUD_TYPE: ('std_msgs/Header header\nuint32 height\nuint32 width\nPointField[] fields\n'
                 'bool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\n'
                 'bool is_dense\n'),
}


def cloud_cdr(stamp_ns: int, frame_id: str, tracks: Sequence[Any]) -> bytes:
    """CDR of the ``end_effectors`` cloud, the same message as the node's
    ``convert.tracks_to_cloud`` (rows :func:`convert.tracks_to_array`, fields
    :data:`convert.ENDEFF_FIELDS`), serialised by rosbags: no rclpy import (about 0.1 s)."""
    from endeff_ros.ros import convert

    store = cloud_typestore()
    t = store.types
    points = convert.tracks_to_array(tracks)
    sec, nanosec = convert.ns_to_sec_nanosec(stamp_ns)
    header = t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](
        sec=sec, nanosec=nanosec), frame_id=str(frame_id))
    fields = [t['sensor_msgs/msg/PointField'](name=n, offset=o, datatype=d, count=c)
              for n, o, d, c in convert.ENDEFF_FIELDS]
    step = convert.ENDEFF_DTYPE.itemsize
    msg = t[CLOUD_TYPE](header=header, height=1, width=len(points), fields=fields,
                        is_bigendian=False, point_step=step, row_step=step * len(points),
                        data=points.view(np.uint8).reshape(-1), is_dense=True)
    return bytes(store.serialize_cdr(msg, CLOUD_TYPE))


@functools.cache
def cloud_typestore() -> Any:
    """A typestore of just the output cloud's types, for the writer's message definition and
    type hash: the same as the Jazzy store's (checked by the tests) at 7 ms instead of the
    0.1-0.15 s that importing the whole Jazzy store costs every run."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    defs: dict[str, Any] = {}
    for name, text in _CLOUD_MSGS.items():
        defs.update(get_types_from_msg(text, name))
    store.register(defs)
    return store


def process_bag(in_path: str | Path, out_path: str | Path, *,
                params: EndeffParams | None = None, options: ReaderOptions | None = None,
                storage: str = 'mcap', force: bool = False, copy_input: bool = False,
                markers: bool = False, marker_lifetime_s: float = 0.2,
                tracker_factory: TrackerFactory | None = None,
                progress: Callable[[int], None] | None = None) -> ProcessResult:
    """Track every frame of ``in_path`` and write ``out_path``; raises :class:`BagError`.

    ``tracker_factory(params)`` (default :class:`Tracker`) builds the tracker; ``progress(n)``
    is called with the number of frames done since the previous call. The output appears only
    when complete: on any error or interrupt nothing is left at ``out_path``'s place.
    """
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import StoragePlugin

    from endeff_ros.ros import convert

    if tracker_factory is None:
        from endeff_ros.core.tracker import Tracker

        tracker_factory = Tracker
    in_path, out_path = Path(in_path), Path(out_path)
    check_output_path(out_path, force=force, inputs=[in_path], own_topics=OUTPUT_TOPICS)
    plugin = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}[storage]
    result = ProcessResult(str(in_path), str(out_path))
    t0 = time.perf_counter()
    sweep_stale_partials(out_path)
    # Written inside a hidden sibling directory (so that the storage file gets the final
    # name), then moved into place.
    tmp_dir = partial_dir(out_path)
    tmp = tmp_dir / out_path.name
    ts = typestore() if markers or copy_input else cloud_typestore()
    remove(tmp_dir)
    try:  # from the directory's creation on: an interrupt there must remove it too
        tmp_dir.mkdir(parents=True)
        with BagReader(in_path, options) as bag:
            assert bag.selection is not None
            result.topics = bag.selection.describe()
            tracker = tracker_factory(params)
            writer = Writer(tmp, version=9, storage_plugin=plugin)
            writer.set_custom_data(WRITER_KEY, WRITER)
            try:
                with writer:
                    c_cloud = writer.add_connection(OUTPUT_CLOUD, CLOUD_TYPE, typestore=ts)
                    c_mark = writer.add_connection(OUTPUT_MARKERS, MARKERS_TYPE,
                                                   typestore=ts) if markers else None
                    buffered: list[tuple[int, int, Any, bytes]] = []
                    for n, rec in enumerate(bag.records(ground_truth=False)):
                        try:
                            res = tracker.update(rec.frame)
                        except InputError:  # as the node: publish an empty result
                            res = SimpleNamespace(tracks=[], estimate=_EMPTY_ESTIMATE)
                            result.empty_frames += 1
                        out = [(c_cloud, cloud_cdr(rec.frame.stamp_ns, rec.frame.frame_id,
                                                   res.tracks))]
                        if c_mark is not None:
                            header = convert.make_header(rec.frame.stamp_ns,
                                                         rec.frame.frame_id)
                            out.append((c_mark, convert.serialize(
                                convert.result_to_markers(header, res, marker_lifetime_s))))
                        for k, (conn, raw) in enumerate(out):
                            if copy_input:
                                buffered.append((rec.log_time_ns, 2 * n + k, conn, raw))
                            else:
                                writer.write(conn, rec.log_time_ns, raw)
                        result.frames += 1
                        if progress is not None:
                            progress(1)
                    if copy_input:
                        _copy_merged(bag, writer, buffered)
            except (OSError, sqlite3.Error) as err:
                failure = write_error(out_path, err)
                if failure is None:
                    raise
                raise failure from err
            result.read_stats = bag.stats.to_dict()
        if result.frames == 0:
            raise BagError(in_path, 'no synchronised frames (colour, depth and camera info '
                                    'never lined up)')
        replace_into_place(tmp, out_path, tmp_dir)
    finally:
        remove(tmp_dir)
    result.seconds = time.perf_counter() - t0
    return result


def _copy_merged(bag: BagReader, writer: Any, outputs: list[tuple[int, int, Any, bytes]]
                 ) -> None:
    """Write every input message (raw) merged by log time with the buffered outputs."""
    from rosbags.interfaces import MessageDefinitionFormat

    ts = typestore()
    mapping: dict[int, Any] = {}
    out_keys: dict[tuple[str, str], Any] = {}
    for conn in bag.reader.connections:
        if conn.topic in OUTPUT_TOPICS:
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
    inputs = ((log, -1, mapping[id(conn)], raw) for conn, log, raw in bag.raw_messages(conns))
    for log, _, conn, raw in heapq.merge(inputs, iter(outputs), key=lambda r: (r[0], r[1])):
        writer.write(conn, log, raw)


# --------------------------------------------------------------------------------------------
# Several bags, several processes
# --------------------------------------------------------------------------------------------

def _job(job: tuple[Any, ...]) -> ProcessResult:
    """Process one bag in a worker; never raises but for an interrupt (an error is in the
    result, naming the bag). SIGTERM from the parent unwinds process_bag, whose cleanup removes
    the partial output (:mod:`endeff_ros.workers`)."""
    in_path, out_path, kwargs = job
    try:
        return process_bag(in_path, out_path, progress=prog.report, **kwargs)
    except BagError as err:
        return ProcessResult(str(in_path), str(out_path), error=str(err))
    except EndeffError as err:
        return ProcessResult(str(in_path), str(out_path), error=f'{in_path}: {err}')
    except Exception as err:
        tb = traceback.format_exc(limit=6)
        return ProcessResult(str(in_path), str(out_path),
                             error=f'{in_path}: {type(err).__name__}: {err}\n{tb}')


def process_bags(inputs: Sequence[str | Path], output: str | Path, *, jobs: int | None = None,
                 show_progress: bool | None = None, **kwargs: Any) -> list[ProcessResult]:
    """Process several bags, one process per bag (``jobs`` at a time); never raises BagError.

    ``kwargs`` go to :func:`process_bag` (``params``, ``options``, ``storage``, ``force``,
    ``copy_input``, ``markers``, ``marker_lifetime_s``, ``tracker_factory``; the factory must be
    picklable). An interrupt (KeyboardInterrupt; ``endeff`` raises its subclass
    ``Terminated`` for SIGTERM) stops the workers, removes their unfinished outputs and
    propagates.
    """
    try:
        outs = output_paths(inputs, output)
    except BagError as err:
        return [ProcessResult(str(i), '', error=str(err)) for i in inputs]
    if len(inputs) > 1:
        Path(output).mkdir(parents=True, exist_ok=True)
    workers = max(1, min(jobs or os.cpu_count() or 1, len(inputs)))
    kwargs = {**kwargs, 'options': options_for_workers(kwargs.get('options') or ReaderOptions(),
                                                       workers)}
    job_list = [(Path(i), o, kwargs) for i, o in zip(inputs, outs, strict=True)]
    enabled = sys.stderr.isatty() if show_progress is None else show_progress
    total = prog.count_frames([j[0] for j in job_list], kwargs.get('options')) \
        if enabled else 0
    with prog.progress_bar(total, enabled=enabled) as bar:
        if workers == 1:
            return [_serial_job(j, bar.update) for j in job_list]
        return _parallel(job_list, workers, bar, outs)


def _serial_job(job: tuple[Any, ...], progress: Callable[[int], None]) -> ProcessResult:
    in_path, out_path, kw = job
    try:
        return process_bag(in_path, out_path, progress=progress, **kw)
    except BagError as err:
        return ProcessResult(str(in_path), str(out_path), error=str(err))
    except EndeffError as err:
        return ProcessResult(str(in_path), str(out_path), error=f'{in_path}: {err}')


def _parallel(job_list: list[tuple[Any, ...]], workers: int, bar: prog.ProgressBar,
              outs: list[Path]) -> list[ProcessResult]:
    try:
        # On an interrupt the workers get SIGTERM, which unwinds their bags.
        return prog.map_in_workers(_job, job_list, workers, bar)
    except BaseException:
        for o in outs:  # what a worker killed too early left
            sweep_stale_partials(o)
        raise


def run(args: argparse.Namespace) -> int:
    """``endeff process``: 0 if every bag was processed, 1 if any failed, 2 on bad options
    or outputs (reported before any bag is read), 130 / 143 when interrupted."""
    params = load_params_option(args.params, 'endeff process')
    try:
        inputs = find_bags(args.inputs)
    except BagError as err:
        print(f'endeff process: {err}', file=sys.stderr)
        return 2
    outs, problems = check_outputs(inputs, args.output, force=args.force)
    for line in problems:
        print(f'endeff process: {line}', file=sys.stderr)
    if problems:
        return 2
    # SIGTERM raises Terminated here: endeff_ros.cli.main installs the handler for every
    # subcommand.
    try:
        results = process_bags(inputs, args.output, jobs=args.jobs, params=params,
                               options=options_from_args(args), storage=args.storage,
                               force=args.force, copy_input=args.copy_input,
                               markers=args.markers, marker_lifetime_s=args.marker_lifetime)
    except KeyboardInterrupt as err:
        for o in outs:
            sweep_stale_partials(o, include_own=True)
        print('endeff process: interrupted; outputs not finished were removed (finished ones '
              'are complete bags)', file=sys.stderr)
        return 143 if isinstance(err, Terminated) else 130
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
