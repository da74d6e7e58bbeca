"""``endeff_node``: RGB-D images in, tracked end-effectors out. Thin wiring around the core.

Subscribes (relative, remappable names) to ``color/image_raw``, ``depth/image_raw`` and
``depth/camera_info``; publishes ``end_effectors`` (PointCloud2), ``end_effectors/markers``
(MarkerArray), optionally ``debug/bands`` and ``debug/image``, and ``/diagnostics``.

Latency never grows: subscription callbacks only synchronise and put the newest set into a
one-item slot; a worker thread takes the newest set, runs the tracker and publishes. Sets the
worker was too slow for are skipped and counted. While a depth image waits for its colour
partner, the worker already runs Sections 3-4 on it (they need no colour); while a colour
image waits for its depth partner, it computes the optical flow (it needs no depth); a colour
image that arrives while the worker estimates its depth partner gets its flow computed in the
subscription callback, on the other core (OpenCV releases the GIL). Either way the partner's
delay and part of the processing overlap. Before subscribing, the node
warms its tracker up (:mod:`endeff_ros.core.warmup`) so that the first frames are not skipped.
"""

from __future__ import annotations

import dataclasses
import gc
import json
import threading
import time
from collections.abc import Callable
from functools import partial
from types import SimpleNamespace
from typing import Any

import cv2
import numpy as np
import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from visualization_msgs.msg import MarkerArray

from endeff_ros.core.errors import InputError, ParameterError
from endeff_ros.core.params import NODE_NAME, EndeffParams, describe
from endeff_ros.core.tracker import Tracker
from endeff_ros.core.warmup import warm_up
from endeff_ros.ros import convert
from endeff_ros.ros.processing import (
    NODE_PARAMS,
    LatestSlot,
    NodeStats,
    flatten,
    take_first,
    updated_params,
    validate_node_changes,
)
from endeff_ros.ros.procs import spin
from endeff_ros.ros.ros_params import descriptor, qos
from endeff_ros.sync import ApproximateTimeSynchronizer

try:
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
except ImportError:  # pragma: no cover - diagnostic_msgs is part of common_interfaces
    DiagnosticArray = None
    from std_msgs.msg import String

_TOPICS = {'color': 'color/image_raw', 'depth': 'depth/image_raw',
           'camera_info': 'depth/camera_info'}


@dataclasses.dataclass(frozen=True)
class _Early:
    """A result computed while its set was incomplete: Sections 3-4 of the depth image
    (``data``: the frame without colour) or the flow to the colour image (``data``: the RGB
    array); with the parameters it used and the milliseconds it took."""

    stamp_ns: int
    data: Any
    result: Any
    params: EndeffParams
    ms: float
    updates: int = 0  # tracker updates done before it was computed (flow: must be current)

    def fits(self, msg: Any, params: EndeffParams) -> bool:
        """Made for this image, with these parameters."""
        return (msg is not None and self.params is params
                and self.stamp_ns == convert.stamp_to_ns(msg.header.stamp))


def _frame(msgs: dict[str, Any], early: _Early | None, early_flow: _Early | None) -> Any:
    """The set's RGBDFrame, reusing what the early work converted (InputError if unusable)."""
    color, depth, info = msgs.get('color'), msgs['depth'], msgs['camera_info']
    if info is None or (early is None and early_flow is None):
        return convert.frame_from_messages(color, depth, info)
    base = early.data if early else convert.frame_from_messages(None, depth, info)
    rgb = (early_flow.data if early_flow else
           None if color is None else convert.color_image_to_array(color))
    return dataclasses.replace(base, color=rgb)


class EndeffNode(Node):
    """The end-effector node. ``tracker_factory(params)`` builds the tracker (tests inject one)."""

    def __init__(self, *, tracker_factory: Callable[[EndeffParams], Any] = Tracker,
                 node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        for row in [*describe(), *NODE_PARAMS]:
            self.declare_parameter(row['name'], row['default'], descriptor(row))
        self.params = EndeffParams.from_dict(
            {row['name']: self.get_parameter(row['name']).value for row in describe()})
        validate_node_changes({r['name']: self._p(r['name']) for r in NODE_PARAMS})
        self.tracker = tracker_factory(self.params)
        if isinstance(self.tracker, Tracker):
            self._warm_up()
        self.stats = NodeStats()
        self._lock = threading.Lock()
        self._slot: LatestSlot[tuple[dict[str, Any], float]] = LatestSlot()
        # Depth images (with the camera info) waiting for the early Sections 3-4, colour images
        # waiting for the early flow, and the last result of each.
        self._early: LatestSlot[tuple[Any, Any]] = self._slot.companion()
        self._early_color: LatestSlot[tuple[Any, Any]] = self._slot.companion()
        self._prepared: _Early | None = None
        self._prepared_flow: _Early | None = None
        # Depth stamp whose early Sections 3-4 the worker is running (None: not running), and
        # the lock that keeps tracker state reads (flow) apart from tracker updates.
        self._estimating_ns: int | None = None
        self._tracker_lock = threading.Lock()
        self._updates = 0
        self._inputs = ['color', 'depth', 'camera_info'] if self._p('use_color') else [
            'depth', 'camera_info']
        self._last_info: Any = None
        self._first_unpaired_depth: float | None = None
        self._newest_ns: int | None = None
        self._reset_pending = False
        self._waiting: dict[int, tuple[Any, float]] = {}  # depth stamp -> (msg, receipt)
        self._floor_ns: int | None = None  # newest depth stamp handed to the worker
        self._params_pending: EndeffParams | None = None
        self._dropped_before = {k: 0 for k in self._inputs}
        self._sync = self._make_sync(self._p('sync_queue_size'), self._p('sync_slop'))
        qos_out = qos(self._p('output_reliability'), 5)
        self.pub_cloud = self.create_publisher(PointCloud2, 'end_effectors', qos_out)
        self.pub_markers = self.create_publisher(MarkerArray, 'end_effectors/markers', qos_out)
        self.pub_bands = self.create_publisher(PointCloud2, 'debug/bands', qos_out)
        self.pub_image = self.create_publisher(Image, 'debug/image', qos_out)
        if DiagnosticArray is not None:
            self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        else:  # pragma: no cover
            self.pub_diag = self.create_publisher(String, '~/statistics', 10)
        qos_in = qos(self._p('input_reliability'), self._p('input_queue_depth'))
        # Camera info first: when several inputs are ready, the executor serves it first.
        self._subs = [self.create_subscription(CameraInfo if kind == 'camera_info' else Image,
                                               _TOPICS[kind], partial(self._on_input, kind),
                                               qos_in) for kind in reversed(self._inputs)]
        self._jump = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1),
                          on_clock_change=False), post_callback=self._on_clock_jump)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._worker = threading.Thread(target=self._run, name='endeff_worker', daemon=True)
        self._worker.start()

    def _warm_up(self) -> None:
        """First-frame costs paid before subscribing (:mod:`endeff_ros.core.warmup`)."""
        t0 = time.perf_counter()
        try:
            warm_up(self.tracker)
        except Exception as exc:  # noqa: BLE001 - a failed warm-up only costs latency
            self.get_logger().warning(f'warm-up failed (first frames may be slow): {exc!r}')
            return
        self.get_logger().debug(f'warm-up took {(time.perf_counter() - t0) * 1e3:.0f} ms')
        # Startup objects (modules, messages, the warm-up's arrays) move out of the collector's
        # generations, so its full passes during the stream are shorter: in 3 alternating
        # pairs of latency_bench runs, p95 0.3-1.7 ms lower above the relay, p99 1-4 ms lower.
        gc.collect()
        gc.freeze()

    # ---------------------------------------------------------------- parameters and inputs
    def _p(self, name: str) -> Any:
        return self.get_parameter(name).value

    def _make_sync(self, queue_size: int, slop_s: float) -> ApproximateTimeSynchronizer:
        sync = ApproximateTimeSynchronizer(len(self._inputs), int(queue_size),
                                           round(float(slop_s) * 1e9),
                                           latched=(self._inputs.index('camera_info'),))
        if self._last_info is not None:
            sync.add(self._inputs.index('camera_info'), 0, self._last_info)
        return sync

    def _replace_sync(self, queue_size: int, slop_s: float) -> None:
        """New synchroniser (caller holds the lock); keeps the drop counts and camera info."""
        for i, kind in enumerate(self._inputs):
            self._dropped_before[kind] += self._sync.stats.dropped[i]
        self._sync = self._make_sync(queue_size, slop_s)

    def dropped(self) -> dict[str, int]:
        """Messages the synchroniser dropped unpaired, per input."""
        return {k: self._dropped_before[k] + self._sync.stats.dropped[i]
                for i, k in enumerate(self._inputs)}

    def _on_input(self, kind: str, msg: Any) -> None:
        receipt = time.monotonic()
        stamp = convert.stamp_to_ns(msg.header.stamp)
        flow_done = kind == 'color' and self._flow_alongside(msg, stamp)
        with self._lock:
            self.stats.received[kind] += 1
            if kind == 'camera_info':
                self._last_info = msg
                self._first_unpaired_depth = None
            elif self._newest_ns is not None and stamp < self._newest_ns - round(
                    self._p('time_jump_threshold') * 1e9):
                self.get_logger().info(f'input stamps jumped back by '
                                       f'{(self._newest_ns - stamp) / 1e9:.3f} s: resetting')
                self._request_reset()
                self._newest_ns = stamp
            else:
                self._newest_ns = max(stamp, self._newest_ns or stamp)
            if kind == 'depth' and self._first_unpaired_depth is None:
                self._first_unpaired_depth = receipt
            if kind == 'depth' and 'color' in self._inputs:
                self._waiting[stamp] = (msg, receipt)
                if self._last_info is not None:
                    self._early.put((msg, self._last_info))
            ready = [self._claim(dict(zip(self._inputs, found)))
                     for found in self._sync.add(self._inputs.index(kind), stamp, msg)]
            if (kind == 'color' and not ready and not flow_done
                    and self._last_info is not None):
                self._early_color.put((msg, self._last_info))
        for msgs in ready:
            if msgs is not None:
                self._slot.put((msgs, receipt))

    def _flow_alongside(self, color: Any, stamp: int) -> bool:
        """Compute the optical flow of a colour image right here, in the subscription
        callback, while the worker runs the early Sections 3-4 of its depth partner: OpenCV
        releases the GIL, so the two run on two cores, and the set is complete with both
        parts done when the worker finishes (otherwise the worker ran the flow after the
        estimate). True if it did."""
        with self._lock:
            estimating, info = self._estimating_ns, self._last_info
            slop = round(self._p('sync_slop') * 1e9)
            if estimating is None or info is None or abs(stamp - estimating) > slop:
                return False
        self.stats.flow_alongside += self._prepare_flow(color, info)
        return True

    def _claim(self, msgs: dict[str, Any]) -> dict[str, Any] | None:
        """Accept a set unless its depth is not newer than one already handed on (lock held)."""
        stamp = convert.stamp_to_ns(msgs['depth'].header.stamp)
        for old in [s for s in self._waiting if s <= stamp]:
            del self._waiting[old]
        if self._floor_ns is not None and stamp <= self._floor_ns:
            self.stats.duplicates += 1
            return None
        self._floor_ns = stamp
        return msgs

    def _flush_colorless(self, now: float) -> None:
        """Hand on the newest depth image that waited ``color_timeout`` for its colour."""
        with self._lock:
            timeout = self._p('color_timeout')
            expired = sorted(s for s, (_, t) in self._waiting.items() if now - t > timeout)
            if not expired or self._last_info is None:
                return
            msg, receipt = self._waiting[expired[-1]]
            for stamp in expired:
                del self._waiting[stamp]
            msgs = self._claim({'color': None, 'depth': msg, 'camera_info': self._last_info})
            self.stats.colorless += msgs is not None
        if msgs is not None:
            self._slot.put((msgs, receipt))

    def _request_reset(self) -> None:
        """Forget the tracks and the synchroniser state (caller holds the lock)."""
        self._reset_pending = True
        self._waiting.clear()
        self._floor_ns = None
        self._replace_sync(self._p('sync_queue_size'), self._p('sync_slop'))
        self._slot.clear()

    def _on_clock_jump(self, jump: Any) -> None:
        if jump.delta.nanoseconds < 0:
            with self._lock:
                self._request_reset()

    def _on_set_parameters(self, params: list[Any]) -> SetParametersResult:
        changes = {p.name: p.value for p in params}
        try:
            validate_node_changes(changes)
            new = updated_params(self.params, changes)
            queue = changes.get('sync_queue_size', self._p('sync_queue_size'))
            slop = changes.get('sync_slop', self._p('sync_slop'))
        except (ParameterError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        with self._lock:
            if new is not self.params:
                self.params = self._params_pending = new
            if 'sync_queue_size' in changes or 'sync_slop' in changes:
                self._replace_sync(queue, slop)
        return SetParametersResult(successful=True)

    # ---------------------------------------------------------------- processing
    def _run(self) -> None:
        next_diag = next_log = time.monotonic()
        while not self._slot.closed:
            got = take_first([self._slot, self._early, self._early_color], timeout=0.02)
            try:
                if got is not None:
                    (self._process, self._prepare, self._prepare_flow)[got[0]](*got[1])
                now = time.monotonic()
                self._flush_colorless(now)
                self._check_camera_info(now)
                if now >= next_diag:
                    next_diag = now + self._p('diagnostics_period')
                    self._publish_diagnostics(log=now >= next_log)
                    if now >= next_log:
                        next_log = now + self._p('log_period')
            except Exception as exc:  # noqa: BLE001 - the worker must survive anything
                if not rclpy.ok(context=self.context):
                    return
                self.stats.errors += 1
                self.get_logger().error(f'processing failed: {exc!r}',
                                        throttle_duration_sec=5)

    def _check_camera_info(self, now: float) -> None:
        """Warn when depth images arrive but camera info has not for half a second."""
        first = self._first_unpaired_depth
        if self._last_info is None and first is not None and now - first > 0.5:
            topic = self.resolve_topic_name(_TOPICS['camera_info'])
            text = f'no camera info received on {topic}: depth images wait for it'
            self.stats.warn('missing_camera_info', text)
            self.get_logger().warning(text, throttle_duration_sec=5)

    def _prepare(self, depth: Any, info: Any) -> None:
        """Sections 3-4 of a depth image whose colour partner has not arrived yet (the
        tracker's :meth:`~endeff_ros.core.tracker.Tracker.estimate`); :meth:`_process` uses
        the result if its set has that depth image and nothing changed in between."""
        estimate_fn = getattr(self.tracker, 'estimate', None)
        stamp = convert.stamp_to_ns(depth.header.stamp)
        with self._lock:
            if (estimate_fn is None or self._params_pending is not None or self._reset_pending
                    or (self._floor_ns is not None and stamp <= self._floor_ns)):
                return
            self._estimating_ns = stamp
        t0 = time.perf_counter()
        try:
            frame = convert.frame_from_messages(None, depth, info)
            if not np.isfinite(frame.depth).any():
                return
            estimate = estimate_fn(frame)
        except InputError:
            return  # _process reports it when the set comes
        finally:
            with self._lock:
                self._estimating_ns = None
        self._prepared = _Early(stamp, frame, estimate, self.tracker.params,
                                (time.perf_counter() - t0) * 1e3)

    def _prepare_flow(self, color: Any, info: Any) -> bool:
        """The optical flow for a colour image, computed before its set is complete (the
        tracker's :meth:`~endeff_ros.core.tracker.Tracker.flow`), for :meth:`_process`; True if
        it was computed."""
        flow_fn = getattr(self.tracker, 'flow', None)
        with self._lock:
            if flow_fn is None or self._params_pending is not None or self._reset_pending:
                return False
        t0 = time.perf_counter()
        try:
            array = convert.color_image_to_array(color)
            with self._tracker_lock:  # the flow reads the tracks and the previous image
                updates = self._updates
                flow = flow_fn(array, convert.camera_info_to_intrinsics(info))
        except InputError:
            return False  # _process reports it when the set comes
        self._prepared_flow = _Early(convert.stamp_to_ns(color.header.stamp), array, flow,
                                     self.tracker.params, (time.perf_counter() - t0) * 1e3,
                                     updates)
        return True

    def _process(self, msgs: dict[str, Any], receipt: float) -> None:
        with self._lock:
            if self._params_pending is not None:
                self.tracker.params, self._params_pending = self._params_pending, None
            if self._reset_pending:
                with self._tracker_lock:
                    self.tracker.reset()
                    self._updates += 1
                self._reset_pending = False
                self.stats.resets += 1
                self._prepared = self._prepared_flow = None
        depth = msgs['depth']
        header = depth.header
        t0 = time.perf_counter()
        # Early results serve only the set they were made for, and only the next set processed
        # (the tracker's state must not have changed in between).
        early, self._prepared = self._prepared, None
        early_flow, self._prepared_flow = self._prepared_flow, None
        params = self.tracker.params
        early = early if early and early.fits(depth, params) else None
        early_flow = early_flow if (early_flow and early_flow.fits(msgs.get('color'), params)
                                    and early_flow.updates == self._updates) else None
        try:
            frame = _frame(msgs, early, early_flow)
        except InputError as exc:
            self.stats.bad_input += 1
            text = f'skipping input frame: {exc}'
            self.stats.warn('bad_input', text)
            self.get_logger().warning(text, throttle_duration_sec=5)
            return
        try:
            if not np.isfinite(frame.depth).any():
                msg = f'depth image {frame.stamp_ns} ns has no valid reading (all 0 or NaN)'
                raise InputError(msg)
            with self._tracker_lock:
                self._updates += 1
                if early is None and early_flow is None:
                    result = self.tracker.update(frame)
                else:
                    result = self.tracker.update(frame, estimate=early and early.result,
                                                 flow=early_flow and early_flow.result)
            self.stats.prepared += early is not None
            self.stats.prepared_flow += bool(early_flow and early_flow.result is not None)
        except InputError as exc:
            text = f'no end-effectors in frame (publishing an empty cloud): {exc}'
            self.stats.warn('empty_frame', text)
            self.get_logger().warning(text, throttle_duration_sec=5)
            result = SimpleNamespace(tracks=[], estimate=None)
        self.pub_cloud.publish(convert.tracks_to_cloud(header, result.tracks))
        # Markers and debug outputs are built only for subscribers (about 2 ms a frame).
        if self.pub_markers.get_subscription_count():
            self.pub_markers.publish(
                convert.result_to_markers(header, result, self._p('marker_lifetime')))
        if (result.estimate is not None and self._p('publish_debug_bands')
                and self.pub_bands.get_subscription_count()):
            self.pub_bands.publish(convert.bands_to_cloud(header, result.estimate))
        if self._p('publish_debug_image') and self.pub_image.get_subscription_count():
            base = frame.color if frame.color is not None else convert.depth_to_rgb(frame.depth)
            image = convert.draw_tracks(base, frame.intrinsics, result.tracks)
            self.pub_image.publish(convert.array_to_image_msg(header, image))
        self.stats.processed += 1
        self.stats.published_empty += not result.tracks
        early_ms = sum(e.ms for e in (early, early_flow) if e is not None)
        self.stats.processing_ms.add((time.perf_counter() - t0) * 1e3 + early_ms)
        self.stats.age_ms.add((time.monotonic() - receipt) * 1e3)
        now_ns = self.get_clock().now().nanoseconds
        self.stats.latency_ms.add((now_ns - frame.stamp_ns) / 1e6)

    # ---------------------------------------------------------------- reporting
    def snapshot(self) -> dict[str, Any]:
        """Counters and timing summaries (what /diagnostics carries)."""
        with self._lock:
            return self.stats.as_dict(dropped=self.dropped(), skipped=self._slot.skipped,
                                      sets=self._slot.put_count)

    def _publish_diagnostics(self, *, log: bool) -> None:
        snap = self.snapshot()
        proc = snap['processing_ms'].get('p95', float('nan'))
        text = (f"{snap['processed']} frames processed, {snap['skipped']} skipped, "
                f"{sum(snap['dropped_unpaired'].values())} dropped unpaired, "
                f"{snap['bad_input']} bad inputs, p95 processing {proc:.1f} ms, "
                f"p95 latency {snap['latency_ms'].get('p95', float('nan')):.1f} ms")
        if log:
            self.get_logger().info(text)
        if DiagnosticArray is None:  # pragma: no cover
            self.pub_diag.publish(String(data=json.dumps(snap)))
            return
        status = DiagnosticStatus(name=f'{self.get_name()}: processing',
                                  hardware_id=self.get_fully_qualified_name(), message=text)
        status.level = DiagnosticStatus.WARN if (
            snap['bad_input'] or snap['errors']) else DiagnosticStatus.OK
        status.values = [KeyValue(key=k, value=v) for k, v in flatten(snap)]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(array)

    def destroy_node(self) -> None:
        for slot in (self._slot, self._early, self._early_color):
            slot.close()
        if self._worker.is_alive() and self._worker is not threading.current_thread():
            self._worker.join(timeout=5.0)
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run endeff_ros endeff_node``."""
    # One OpenCV thread: the node already runs DDS, executor and worker threads, and on a
    # robot's shared CPU a second flow thread only adds contention (measured: latency_bench).
    cv2.setNumThreads(1)
    spin(EndeffNode, args)


if __name__ == '__main__':
    main()
