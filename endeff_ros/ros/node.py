"""``endeff_node``: RGB-D images in, tracked end-effectors out. Thin wiring around the core.

Subscribes (relative, remappable names) to ``color/image_raw``, ``depth/image_raw`` and
``depth/camera_info``; publishes ``end_effectors`` (PointCloud2), ``end_effectors/markers``
(MarkerArray), optionally ``debug/bands`` and ``debug/image``, and ``/diagnostics``.

Latency never grows: subscription callbacks hand their messages to the ROS-free
:class:`~endeff_ros.ros.scheduler.Scheduler` (synchronisation, newest set wins, early work,
colourless frames, resets); a worker thread takes its next job, runs the tracker and
publishes. A colour image that arrives while the worker estimates its depth partner gets its
flow computed in the subscription callback, on the other core (OpenCV releases the GIL).
Before subscribing, the node warms its tracker up (:mod:`endeff_ros.core.warmup`) so that the
first frames are not skipped.
"""

from __future__ import annotations

import dataclasses
import gc
import json
import sys
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
from rclpy.clock import Clock, ClockType, JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, PointCloud2
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from endeff_ros.core.errors import InputError, ParameterError
from endeff_ros.core.params import NODE_NAME, EndeffParams, describe
from endeff_ros.core.tracker import Tracker
from endeff_ros.core.warmup import warm_up
from endeff_ros.ros import convert
from endeff_ros.ros.executable import spin
from endeff_ros.ros.processing import (
    NODE_PARAMS,
    NodeStats,
    flatten,
    updated_params,
    validate_node_changes,
)
from endeff_ros.ros.ros_params import descriptor, qos
from endeff_ros.ros.scheduler import Early, Scheduler

try:
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
except ImportError:  # pragma: no cover - diagnostic_msgs is part of common_interfaces
    DiagnosticArray = None
    from std_msgs.msg import String

_TOPICS = {'color': 'color/image_raw', 'depth': 'depth/image_raw',
           'camera_info': 'depth/camera_info'}
#: image_transport's compressed topics of the image inputs (``compressed``, ``compressedDepth``).
_COMPRESSED = {'color': 'color/image_raw/compressed', 'depth': 'depth/image_raw/compressedDepth'}
#: Smaller images cannot hold a scene: skipped as bad input instead of emptying the tracks.
MIN_IMAGE_SIDE = 8
#: How often ``image_transport: auto`` looks for publishers until an image input has a message.
_AUTO_PERIOD_S = 0.5
#: An input silent this long (s) is named in a warning, repeated at this period while it stays
#: silent: a node that waits for a camera that is not there (a topic not remapped, a driver
#: not started, another ROS domain) says so instead of sitting there quietly.
NO_INPUT_WARN_S = 5.0

USAGE = """usage: endeff_node [-h] [--ros-args [-r __ns:=/camera] [-r FROM:=TO ...]
                   [--params-file FILE] [-p NAME:=VALUE ...]]

End-effectors of people and articulated entities in an RGB-D stream, tracked over time
(Lin, Pardas & Casas, 2016).

subscribes (relative names, remappable with -r):
  color/image_raw       sensor_msgs/Image (rgb8, bgr8, rgba8, bgra8, mono8); optional (use_color)
  depth/image_raw       sensor_msgs/Image registered to colour: 16UC1 mm or 32FC1 m
  depth/camera_info     sensor_msgs/CameraInfo
  (image_transport compressed/auto: .../compressed, .../compressedDepth)
publishes:
  end_effectors         sensor_msgs/PointCloud2: x y z id entity geodesic confidence vx vy vz
                        state kind (docs/output.md)
  end_effectors/markers visualization_msgs/MarkerArray (built only for subscribers)
  debug/bands, debug/image (optional), /diagnostics
services:
  ~/reset_background          std_srvs/Trigger: learn the static background again
                              (what is in view and has end-effectors stays: people first)
  ~/learn_empty_background    std_srvs/Trigger: the room is empty of people now: learn
                              everything in view as background (a fixed camera's furniture)

ROS arguments follow --ros-args:
  -r __ns:=/camera                    namespace of the topics above
  -r depth/image_raw:=/other/topic    remap one input to a driver's topic
  --params-file config/endeff.yaml    parameters (`endeff params` lists them all)
  -p use_color:=false                 one parameter

example:
  endeff_node --ros-args -r __ns:=/camera --params-file config/endeff.yaml

options:
  -h, --help  show this help and exit
"""


def _stamp(msg: Any) -> int:
    """Header stamp of a message, ns."""
    return convert.stamp_to_ns(msg.header.stamp)


def _frame(msgs: dict[str, Any], early: Early | None, early_flow: Early | None) -> Any:
    """The set's RGBDFrame, reusing what the early work converted (InputError if unusable)."""
    color, depth, info = msgs.get('color'), msgs['depth'], msgs['camera_info']
    if info is None or (early is None and early_flow is None):
        return convert.frame_from_messages(color, depth, info)
    base = early.data if early else convert.frame_from_messages(None, depth, info)
    rgb = (early_flow.data if early_flow else
           None if color is None else convert.any_color_to_array(color))
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
        self.scheduler = Scheduler(
            use_color=self._p('use_color'), queue_size=self._p('sync_queue_size'),
            slop_ns=round(self._p('sync_slop') * 1e9), color_timeout_s=self._p('color_timeout'),
            jump_threshold_ns=round(self._p('time_jump_threshold') * 1e9), stamp_of=_stamp,
            stats=self.stats, on_event=self.get_logger().info, on_warning=self._warn)
        # Keeps tracker state reads (flow) apart from tracker updates; ``_updates`` counts the
        # updates, so that an early flow computed before the latest one is not used.
        self._tracker_lock = threading.Lock()
        self._updates = 0
        qos_out = qos(self._p('output_reliability'), 5)
        self.pub_cloud = self.create_publisher(PointCloud2, 'end_effectors', qos_out)
        self.pub_markers = self.create_publisher(MarkerArray, 'end_effectors/markers', qos_out)
        self.pub_bands = self.create_publisher(PointCloud2, 'debug/bands', qos_out)
        self.pub_image = self.create_publisher(Image, 'debug/image', qos_out)
        if DiagnosticArray is not None:
            self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        else:  # pragma: no cover
            self.pub_diag = self.create_publisher(String, '~/statistics', 10)
        self._qos_in = qos(self._p('input_reliability'), self._p('input_queue_depth'))
        transport = self._p('image_transport')
        # Camera info first: when several inputs are ready, the executor serves it first.
        self._subs = {kind: self._subscribe(kind, compressed=transport == 'compressed'
                                            and kind != 'camera_info')
                      for kind in reversed(self.scheduler.inputs)}
        self._auto = self.create_timer(_AUTO_PERIOD_S, self._choose_transport) if (
            transport == 'auto') else None
        self._jump = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1),
                          on_clock_change=False), post_callback=self._on_clock_jump)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.srv_reset_background = self.create_service(Trigger, '~/reset_background',
                                                        self.reset_background)
        self.srv_learn_empty = self.create_service(Trigger, '~/learn_empty_background',
                                                   self.learn_empty_background)
        self._worker = threading.Thread(target=self._run, name='endeff_worker', daemon=True)
        self._worker.start()
        self._heard = dict(self.stats.received)
        self._silence = self.create_timer(NO_INPUT_WARN_S, self._warn_silent_inputs,
                                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f'waiting for {_listing(self._input_topics())}')

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
        # generations, so its full passes during the stream are shorter (docs/design.md).
        gc.collect()
        gc.freeze()

    # ---------------------------------------------------------------- parameters and inputs
    def _p(self, name: str) -> Any:
        return self.get_parameter(name).value

    def _warn(self, kind: str, text: str) -> None:
        """A problem with the input: counted per kind and logged at most every 5 s."""
        self.stats.warn(kind, text)
        self.get_logger().warning(text, throttle_duration_sec=5)

    def _subscribe(self, kind: str, *, compressed: bool) -> Any:
        if kind == 'camera_info':
            return self.create_subscription(CameraInfo, _TOPICS[kind],
                                            partial(self._on_input, kind), self._qos_in)
        topic, msg_type = (_COMPRESSED[kind], CompressedImage) if compressed else (
            _TOPICS[kind], Image)
        return self.create_subscription(msg_type, topic, partial(self._on_input, kind),
                                        self._qos_in)

    def _choose_transport(self) -> None:
        """``image_transport: auto``: an image input that has had no message yet, whose raw
        topic has no publisher while its compressed topic has one, switches to the compressed
        topic. Stops looking once every image input has had a message."""
        waiting = [k for k in ('color', 'depth') if k in self._subs
                   and not self.stats.received[k]]
        for kind in waiting:
            raw, packed = (self.resolve_topic_name(t) for t in (_TOPICS[kind], _COMPRESSED[kind]))
            if (self._subs[kind].topic_name == raw and not self.count_publishers(raw)
                    and self.count_publishers(packed)):
                self.get_logger().info(f'{raw} has no publisher: subscribing to {packed}')
                self.destroy_subscription(self._subs[kind])
                self._subs[kind] = self._subscribe(kind, compressed=True)
        if not waiting and self._auto is not None:
            self._auto.cancel()

    def _input_topics(self, kinds: Any = None) -> list[str]:
        """Resolved names of the subscribed inputs (of ``kinds``), depth first."""
        order = [k for k in ('depth', 'camera_info', 'color') if k in self._subs]
        return [self._subs[k].topic_name for k in order if kinds is None or k in kinds]

    def _warn_silent_inputs(self) -> None:
        """Every NO_INPUT_WARN_S (steady time: a simulated clock that has not started does not
        stop it): name the inputs that received nothing since the previous call."""
        silent = [k for k, n in self.stats.received.items()
                  if k in self._subs and n == self._heard.get(k, 0)]
        self._heard = dict(self.stats.received)
        if silent:
            self.get_logger().warning(
                f'no message for {NO_INPUT_WARN_S:g} s on {_listing(self._input_topics(silent))}'
                ' (is the camera driver running, on this ROS_DOMAIN_ID, and are the inputs '
                'remapped to its topics? `ros2 topic list` shows them)')

    def dropped(self) -> dict[str, int]:
        """Messages the synchroniser dropped unpaired, per input."""
        return self.scheduler.dropped()

    def _on_input(self, kind: str, msg: Any) -> None:
        receipt = time.monotonic()
        flow_done = kind == 'color' and self._flow_alongside(msg)
        self.scheduler.on_input(kind, msg, receipt, flow_done=flow_done)

    def _flow_alongside(self, color: Any) -> bool:
        """Compute the optical flow of a colour image right here, in the subscription
        callback, while the worker runs the early Sections 3-4 of its depth partner: OpenCV
        releases the GIL, so the two run on two cores, and the set is complete with both
        parts done when the worker finishes (otherwise the worker ran the flow after the
        estimate). True if it did."""
        info = self.scheduler.flow_alongside_info(_stamp(color))
        if info is None:
            return False
        self.stats.flow_alongside += self._prepare_flow(color, info)
        return True

    def _on_clock_jump(self, jump: Any) -> None:
        if jump.delta.nanoseconds < 0:
            self.scheduler.request_reset()

    def reset_background(self, _request: Any, response: Any) -> Any:
        """``~/reset_background`` (std_srvs/Trigger): the static background is re-learnt from
        the next frame; the tracks are kept, and what is in view with end-effectors stays
        foreground (``background_keep_initial``). Only sets a flag the worker reads, so it
        needs no lock."""
        return self._relearn(response, 'reset_background', empty=False)

    def learn_empty_background(self, _request: Any, response: Any) -> Any:
        """``~/learn_empty_background`` (std_srvs/Trigger): the caller says the room is empty
        of people now, so everything in view while the background learns is background,
        furniture with end-effectors included; people who come in later are foreground."""
        return self._relearn(response, 'learn_empty_background', empty=True)

    def _relearn(self, response: Any, name: str, *, empty: bool) -> Any:
        reset = getattr(self.tracker, 'reset_background', None)
        if reset is None:
            response.success = False
            response.message = 'this tracker has no static background'
            return response
        reset(empty=empty)
        response.success = True
        what = 'learnt as the empty room' if empty else 're-learnt'
        response.message = (f'the background is {what} from the next frame' if
                            self.params.background else 'the background is off (parameter '
                            'background): it will be learnt afresh when turned on')
        self.get_logger().info(f'{name}: {response.message}')
        return response

    def _on_set_parameters(self, params: list[Any]) -> SetParametersResult:
        changes = {p.name: p.value for p in params}
        try:
            validate_node_changes(changes)
            new = updated_params(self.params, changes)
            queue = changes.get('sync_queue_size', self._p('sync_queue_size'))
            slop = changes.get('sync_slop', self._p('sync_slop'))
        except (ParameterError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if new is not self.params:
            self.params = new
            self.scheduler.change_params(new)
        if 'sync_queue_size' in changes or 'sync_slop' in changes:
            self.scheduler.resync(queue, round(slop * 1e9))
        if 'color_timeout' in changes:
            self.scheduler.color_timeout_s = float(changes['color_timeout'])
        if 'time_jump_threshold' in changes:
            self.scheduler.jump_threshold_ns = round(changes['time_jump_threshold'] * 1e9)
        return SetParametersResult(successful=True)

    # ---------------------------------------------------------------- processing
    def _run(self) -> None:
        next_diag = next_log = time.monotonic()
        jobs = {'process': self._process, 'prepare': self._prepare,
                'prepare_flow': self._prepare_flow}
        while not self.scheduler.closed:
            got = self.scheduler.next_job(timeout=0.02)
            try:
                if got is not None:
                    jobs[got[0]](*got[1])
                now = time.monotonic()
                self.scheduler.flush_colorless(now)
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
        if self.scheduler.missing_camera_info(now):
            topic = self.resolve_topic_name(_TOPICS['camera_info'])
            text = f'no camera info received on {topic}: depth images wait for it'
            self.stats.warn('missing_camera_info', text)
            self.get_logger().warning(text, throttle_duration_sec=5)

    def _prepare(self, depth: Any, info: Any) -> None:
        """Sections 3-4 of a depth image whose colour partner has not arrived yet (the
        tracker's :meth:`~endeff_ros.core.tracker.Tracker.estimate`); :meth:`_process` uses
        the result if its set has that depth image and nothing changed in between."""
        estimate_fn = getattr(self.tracker, 'estimate', None)
        # While the static background learns, the frame's own colour decides: no early work.
        if (estimate_fn is None or getattr(self.tracker, 'estimate_wants_color', False)
                or not self.scheduler.begin_estimate(depth)):
            return
        t0 = time.perf_counter()
        early = None
        try:
            frame = convert.frame_from_messages(None, depth, info)
            if np.isfinite(frame.depth).any():
                early = Early(_stamp(depth), frame, estimate_fn(frame), self.tracker.params,
                              (time.perf_counter() - t0) * 1e3)
        except InputError:
            pass  # _process reports it when the set comes
        finally:
            self.scheduler.end_estimate(early)

    def _prepare_flow(self, color: Any, info: Any) -> bool:
        """The optical flow for a colour image, computed before its set is complete (the
        tracker's :meth:`~endeff_ros.core.tracker.Tracker.flow`), for :meth:`_process`; True if
        it was computed."""
        flow_fn = getattr(self.tracker, 'flow', None)
        if flow_fn is None or not self.scheduler.may_flow():
            return False
        t0 = time.perf_counter()
        try:
            array = convert.any_color_to_array(color)
            with self._tracker_lock:  # the flow reads the tracks and the previous image
                updates = self._updates
                flow = flow_fn(array, convert.camera_info_to_intrinsics(info))
        except InputError:
            return False  # _process reports it when the set comes
        self.scheduler.store_flow(Early(_stamp(color), array, flow, self.tracker.params,
                                        (time.perf_counter() - t0) * 1e3, updates))
        return True

    def _process(self, msgs: dict[str, Any], receipt: float) -> None:
        params, reset = self.scheduler.begin_set()
        if params is not None:
            self.tracker.params = params
        if reset:
            with self._tracker_lock:
                self.tracker.reset()
                self._updates += 1
            self.stats.resets += 1
        header = msgs['depth'].header
        t0 = time.perf_counter()
        early, early_flow = self.scheduler.take_early(msgs, self.tracker.params, self._updates)
        try:
            frame = _frame(msgs, early, early_flow)
            if min(frame.depth.shape) < MIN_IMAGE_SIDE:
                msg = (f'depth image {frame.depth.shape[1]}x{frame.depth.shape[0]} is too small '
                       f'to hold a scene (tracks kept)')
                raise InputError(msg)
        except InputError as exc:
            self.stats.bad_input += 1
            self._warn('bad_input', f'skipping input frame: {exc}')
            return
        if not header.frame_id:
            self._warn('empty_frame_id', 'depth image has an empty frame_id: the outputs carry '
                       "it as it is (set the driver's frame_id)")
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
        return self.stats.as_dict(dropped=self.dropped(), skipped=self.scheduler.skipped,
                                  sets=self.scheduler.sets)

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
        self.scheduler.close()
        if self._worker.is_alive() and self._worker is not threading.current_thread():
            self._worker.join(timeout=5.0)
        super().destroy_node()


def _listing(names: list[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return ' and '.join(names) if len(names) < 3 else f'{", ".join(names[:-1])} and {names[-1]}'


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run endeff_ros endeff_node``: ``-h`` / ``--help`` before
    ``--ros-args`` prints the usage and exits (it used to start the node)."""
    argv = sys.argv[1:] if args is None else list(args)
    own = argv[:argv.index('--ros-args')] if '--ros-args' in argv else argv
    if '-h' in own or '--help' in own:
        print(USAGE, end='')
        return 0
    # One OpenCV thread: the node already runs DDS, executor and worker threads, and on a
    # robot's shared CPU a second flow thread only adds contention.
    cv2.setNumThreads(1)
    spin(EndeffNode, args)
    return 0


if __name__ == '__main__':
    sys.exit(main())
