"""In-process tests of endeff_node with an injected fake tracker (plumbing, bad input, params)."""

from __future__ import annotations

import itertools
import threading
import time

import numpy as np
import pytest
import rclpy
from ros_helpers import image_msg, info_msg, spin_until

from endeff_ros.core.errors import InputError, ParameterError
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.single_frame import EntityEstimate, FrameEstimate
from endeff_ros.core.tracker import TrackerResult
from endeff_ros.core.types import RGBDFrame, Track
from endeff_ros.ros import convert
from endeff_ros.ros.processing import LatestSlot

pytestmark = pytest.mark.integration

W, H = 32, 24
FRAME_ID = 'camera_depth_optical_frame'
_ns = itertools.count()


class FakeTracker:
    """Finds one 'end-effector' at the nearest valid depth pixel; nothing beyond 3 m."""

    instances: list[FakeTracker] = []

    def __init__(self, params: EndeffParams) -> None:
        self.params = params
        self.frames: list[RGBDFrame] = []
        self.params_seen: list[EndeffParams] = []
        self.resets = 0
        FakeTracker.instances.append(self)

    def reset(self) -> None:
        self.resets += 1

    def update(self, frame: RGBDFrame) -> TrackerResult:
        self.frames.append(frame)
        self.params_seen.append(self.params)
        assert np.isfinite(frame.depth).any(), 'the node must not pass all-NaN depth on'
        if np.nanmin(frame.depth) > 8.0:
            msg = 'nothing in front of the camera'
            raise InputError(msg)
        v, u = np.unravel_index(np.nanargmin(frame.depth), frame.depth.shape)
        z = float(frame.depth[v, u])
        k = frame.intrinsics
        p = np.array([(u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z])
        tracks = [] if z > 3.0 else [
            Track(id=4, entity=0, position=p, geodesic=0.8, confidence=0.9, state=0, age=1,
                  path=np.stack([p, p + [0, 0.1, 0], p + [0, 0.3, 0]]))]
        root = p + [0, 0.3, 0]
        estimate = FrameEstimate(points=p[None], band=np.zeros(1, int), subband=np.zeros(1, int),
                                 entity=np.zeros(1, int), unreachable=0, entities=[
                                     EntityEstimate(0, root, [], None, np.zeros(1, int))])
        return TrackerResult(frame.stamp_ns, frame.frame_id, tracks, estimate)


def _depth_image(stamp_ns: int, depth_m: float = 1.5, frame_id: str = FRAME_ID) -> object:
    """A 16UC1 depth image: background at 3.8 m, one pixel at ``depth_m`` (FakeTracker's end)."""
    mm = np.full((H, W), 3800, np.uint16)
    mm[5, 7] = round(depth_m * 1000)
    return image_msg(mm, '16UC1', stamp_ns, frame_id)


def _colour_image(stamp_ns: int, value: int = 90) -> object:
    """A uniform rgb8 colour image stamped ``stamp_ns``."""
    return image_msg(np.full((H, W, 3), value, np.uint8), 'rgb8', stamp_ns, 'color_frame')


class Harness:
    """The node under test plus a tester node that feeds inputs and collects outputs."""

    def __init__(self, overrides: dict | None = None, tracker_factory: type = FakeTracker) -> None:
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.parameter import Parameter
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import CameraInfo, Image, PointCloud2
        from visualization_msgs.msg import MarkerArray

        from endeff_ros.ros.node import EndeffNode

        overrides = overrides or {}
        self.ns = f'/t{next(_ns)}'
        params = [Parameter(k, value=v) for k, v in overrides.items()]
        self.node = EndeffNode(tracker_factory=tracker_factory, namespace=self.ns,
                               parameter_overrides=params)
        self.tracker: FakeTracker = self.node.tracker
        self.tester = rclpy.create_node('tester', namespace=self.ns)
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.pub = {'info': self.tester.create_publisher(CameraInfo, 'depth/camera_info', qos)}
        if overrides.get('image_transport', 'raw') == 'raw':  # else the test publishes
            self.pub['color'] = self.tester.create_publisher(Image, 'color/image_raw', qos)
            self.pub['depth'] = self.tester.create_publisher(Image, 'depth/image_raw', qos)
        self.clouds: list = []
        self.markers: list = []
        self.tester.create_subscription(PointCloud2, 'end_effectors', self.clouds.append, qos)
        self.markers_sub = self.tester.create_subscription(
            MarkerArray, 'end_effectors/markers', self.markers.append, qos)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.executor.add_node(self.tester)
        inputs = [p for k, p in self.pub.items() if k != 'color' or overrides.get(
            'use_color', True)]
        assert spin_until(self.executor, lambda: all(
            p.get_subscription_count() > 0 for p in inputs) and
            self.node.pub_cloud.get_subscription_count() > 0 and
            self.node.pub_markers.get_subscription_count() > 0), 'discovery failed'

    def send(self, stamp_ns: int, *, depth_m: float = 1.5, color: bool = True, info=True,
             depth_msg=None, color_msg=None, info_f: float = 500.0) -> None:
        if info:  # camera info first, and received, so the set pairs with this one
            count = self.node.stats.received['camera_info']
            self.pub['info'].publish(info_msg(stamp_ns, FRAME_ID, W, H, info_f))
            assert spin_until(self.executor,
                              lambda: self.node.stats.received['camera_info'] > count)
        if color:
            self.pub['color'].publish(color_msg or _colour_image(stamp_ns + 3_000_000))
        self.pub['depth'].publish(_depth_image(stamp_ns, depth_m) if depth_msg is None
                                  else depth_msg)

    def wait_clouds(self, n: int) -> bool:
        return spin_until(self.executor, lambda: len(self.clouds) >= n and
                          len(self.markers) >= n)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.tester.destroy_node()


@pytest.fixture
def harness(ros_context):
    made: list[Harness] = []

    def make(tracker_factory: type = FakeTracker, **overrides) -> Harness:
        made.append(Harness(overrides, tracker_factory))
        return made[-1]

    yield make
    for h in made:
        h.close()


def test_stamp_frame_and_markers_propagate(harness):
    h = harness()
    h.send(1_000_000_000_123)
    assert h.wait_clouds(1)
    cloud = h.clouds[0]
    assert convert.stamp_to_ns(cloud.header.stamp) == 1_000_000_000_123
    assert cloud.header.frame_id == FRAME_ID
    points = convert.cloud_to_array(cloud)
    assert list(points['id']) == [4]
    np.testing.assert_allclose(points['z'], [1.5], rtol=1e-6)
    frame = h.tracker.frames[0]
    assert frame.color is not None and frame.color.shape == (H, W, 3)
    spheres = [m for m in h.markers[0].markers if m.ns == convert.NS_EFFECTOR]
    assert [m.id for m in spheres] == list(points['id'])
    np.testing.assert_allclose([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                                for m in spheres], convert.xyz(points), atol=1e-6)
    assert all(m.header.frame_id == FRAME_ID and convert.stamp_to_ns(m.header.stamp) ==
               1_000_000_000_123 for m in h.markers[0].markers)
    assert h.markers[0].markers[0].action == 3  # DELETEALL first


def test_empty_cloud_when_nothing_found(harness):
    h = harness()
    h.send(2_000_000_000, depth_m=3.5)
    assert h.wait_clouds(1)
    assert h.clouds[0].width == 0 and convert.stamp_to_ns(h.clouds[0].header.stamp) == 2e9
    assert [m.ns for m in h.markers[0].markers if m.action == 0] == [convert.NS_ROOT]


def test_markers_are_built_only_for_subscribers(harness, monkeypatch):
    h = harness()
    calls: list[int] = []
    build = convert.result_to_markers
    monkeypatch.setattr(convert, 'result_to_markers',
                        lambda *a, **k: calls.append(1) or build(*a, **k))
    h.send(4_000_000_000)
    assert h.wait_clouds(1) and len(calls) == 1  # a subscriber: built and published
    h.tester.destroy_subscription(h.markers_sub)
    assert spin_until(h.executor, lambda: h.node.pub_markers.get_subscription_count() == 0)
    h.send(4_100_000_000)
    assert spin_until(h.executor, lambda: len(h.clouds) >= 2)
    assert len(calls) == 1  # nobody listens: the cloud is published, the markers not built


def test_depth_only_mode(harness):
    h = harness(use_color=False)
    h.send(3_000_000_000, color=False)
    assert h.wait_clouds(1)
    assert h.tracker.frames[0].color is None


def _bad(kind: str) -> dict:
    if kind == 'zero_k':
        return {'info_f': 0.0}
    if kind == 'encoding':
        return {'depth_msg': image_msg(np.zeros((H, W), np.uint8), 'mono8', 0, FRAME_ID)}
    if kind == 'size_mismatch':
        return {'color_msg': image_msg(np.zeros((H * 2, W * 2, 3), np.uint8), 'rgb8', 0, 'c')}
    if kind == 'empty_foreground':  # the tracker's own InputError
        return {'depth_msg': image_msg(np.full((H, W), 9000, np.uint16), '16UC1', 0, FRAME_ID)}
    return {'depth_msg': image_msg(np.zeros((H, W), np.uint16), '16UC1', 0, FRAME_ID)}


@pytest.mark.parametrize('kind,text,publishes', [
    ('zero_k', 'calibrated', False), ('encoding', "'mono8'", False),
    ('size_mismatch', 'colour image', False), ('all_nan', 'no valid reading', True),
    ('empty_foreground', 'nothing in front', True)])
def test_bad_input_warns_and_keeps_running(harness, kind, text, publishes):
    h = harness()
    stamp = 5_000_000_000
    bad = _bad(kind)
    for key in ('depth_msg', 'color_msg'):
        if key in bad:
            bad[key].header.stamp.sec = 5
            if key == 'color_msg':
                bad[key].header.stamp.nanosec = 3_000_000
    h.send(stamp, **bad)
    assert spin_until(h.executor, lambda: h.node.stats.last_warning != '')
    assert text in h.node.stats.last_warning
    if publishes:  # empty foreground: an empty cloud for that stamp
        assert h.wait_clouds(1) and h.clouds[0].width == 0
    else:  # undecodable input: nothing published, but counted
        assert h.node.stats.bad_input == 1
    h.send(stamp + 100_000_000)
    assert spin_until(h.executor, lambda: any(c.width == 1 for c in h.clouds))
    assert convert.stamp_to_ns(h.clouds[-1].header.stamp) == stamp + 100_000_000


def test_missing_camera_info_warns_then_recovers(harness):
    h = harness()
    h.send(7_000_000_000, info=False)
    assert spin_until(h.executor, lambda: 'camera info' in h.node.stats.last_warning)
    assert h.node.stats.received['depth'] == 1
    assert h.node.stats.warnings['missing_camera_info'] >= 1 and not h.clouds
    h.send(7_100_000_000)
    assert h.wait_clouds(1)


def test_runtime_parameters(harness):
    from rclpy.parameter import Parameter

    h = harness(band_delta=0.09, sync_slop=0.01)
    assert h.tracker.params.band_delta == 0.09
    desc = h.node.describe_parameter('band_delta')
    assert 'δ_L' in desc.description and desc.floating_point_range[0].to_value == 1.0
    assert h.node.describe_parameter('flow_method').read_only
    ok = h.node.set_parameters([Parameter('band_delta', value=0.12)])[0]
    assert ok.successful
    h.send(8_000_000_000)
    assert h.wait_clouds(1)
    assert h.tracker.params_seen[-1].band_delta == 0.12
    for name, value, reason in [('band_delta', 5.0, 'range'),
                                ('box_min_z', 6.0, 'box_min_z'),  # beyond box_max_z
                                ('flow_method', 'farneback', 'read-only'),
                                ('min_entity_points', 1.5, 'type')]:
        result = h.node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful and reason in result.reason, (name, result.reason)
    assert h.node.params.band_delta == 0.12 and h.node.params.box_min_z == 0.4
    assert h.node.set_parameters([Parameter('sync_slop', value=0.03)])[0].successful
    assert h.node.scheduler.slop_ns == 30_000_000
    h.send(8_100_000_000, info=False)  # the new synchroniser kept the latched camera info
    assert h.wait_clouds(2)
    bad = h.node.set_parameters([Parameter('input_reliability', value='reliable')])[0]
    assert not bad.successful and 'read-only' in bad.reason


def test_stamps_jumping_back_reset_tracker(harness):
    h = harness()
    h.send(100_000_000_000)
    assert h.wait_clouds(1)
    h.send(10_000_000_000)
    assert h.wait_clouds(2)
    assert h.tracker.resets == 1
    assert convert.stamp_to_ns(h.clouds[1].header.stamp) == 10_000_000_000


def test_diagnostics_published(harness):
    from diagnostic_msgs.msg import DiagnosticArray

    h = harness(diagnostics_period=0.2)
    got: list = []
    h.tester.create_subscription(DiagnosticArray, '/diagnostics', got.append, 10)
    h.send(11_000_000_000)
    assert h.wait_clouds(1)
    assert spin_until(h.executor, lambda: any(
        ('processed', '1') in [(v.key, v.value) for s in a.status for v in s.values]
        for a in got))


def test_latest_slot_skips_unconsumed():
    slot: LatestSlot[int] = LatestSlot()
    for i in range(5):
        slot.put(i)
    assert slot.take(0) == 4 and slot.skipped == 4
    assert slot.take(0) is None
    slot.close()
    assert slot.take(None) is None


def test_take_first_prefers_the_first_slot_and_wakes_on_any():
    import threading

    from endeff_ros.ros.processing import take_first

    sets: LatestSlot[str] = LatestSlot()
    early = sets.companion()
    early.put('depth 2')
    sets.put('set 1')
    assert take_first([sets, early], 0) == (0, 'set 1')  # complete sets first
    assert take_first([sets, early], 0) == (1, 'depth 2')
    assert take_first([sets, early], 0) is None
    timer = threading.Timer(0.05, early.put, args=('depth 3',))
    timer.start()
    t0 = time.monotonic()
    assert take_first([sets, early], 5.0) == (1, 'depth 3')  # a put on either slot wakes it
    assert time.monotonic() - t0 < 2.0
    sets.close()
    assert take_first([sets, early], None) is None


def test_depth_without_colour_is_processed_colourless_once(harness):
    h = harness(color_timeout=0.05)
    h.send(12_000_000_000, color=False)
    assert h.wait_clouds(1)
    assert h.tracker.frames[0].color is None and h.node.stats.colorless == 1
    # Its colour arriving late must not produce a second cloud for the same stamp.
    h.pub['color'].publish(image_msg(np.zeros((H, W, 3), np.uint8), 'rgb8', 12_003_000_000,
                                     'color_frame'))
    assert spin_until(h.executor, lambda: h.node.stats.duplicates == 1)
    h.send(12_100_000_000)
    assert h.wait_clouds(2)
    assert [convert.stamp_to_ns(c.header.stamp) for c in h.clouds] == [12_000_000_000,
                                                                       12_100_000_000]
    assert h.tracker.frames[1].color is not None


def test_sim_time_jumping_back_resets_tracker(harness):
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    h = harness(use_sim_time=True)
    clock_pub = h.tester.create_publisher(
        Clock, '/clock', QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    assert spin_until(h.executor, lambda: clock_pub.get_subscription_count() > 0)

    def tick(sec: int) -> None:
        clock_pub.publish(Clock(clock=convert.make_header(sec * 10**9, '').stamp))
        assert spin_until(h.executor, lambda: h.node.get_clock().now().nanoseconds == sec * 1e9)

    tick(100)
    tick(101)
    h.send(101_000_000_000)
    assert h.wait_clouds(1)
    assert h.tracker.resets == 0
    tick(50)  # bag replay restarted: /clock jumps back
    h.send(101_100_000_000)  # (input stamps did not jump: only the clock did)
    assert h.wait_clouds(2)
    assert h.tracker.resets == 1


def test_real_tracker_on_a_synthetic_person(ros_context):
    """Default tracker factory (the real core) end to end in-process."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, Image, PointCloud2

    from endeff_ros import synth
    from endeff_ros.ros.node import EndeffNode

    frame = synth.render_person_frame('t_pose')
    k = frame.intrinsics
    node = EndeffNode(namespace='/real')
    tester = rclpy.create_node('tester', namespace='/real')
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    pubs = [tester.create_publisher(CameraInfo, 'depth/camera_info', qos),
            tester.create_publisher(Image, 'color/image_raw', qos),
            tester.create_publisher(Image, 'depth/image_raw', qos)]
    clouds: list = []
    tester.create_subscription(PointCloud2, 'end_effectors', clouds.append, qos)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    executor.add_node(tester)
    try:
        assert spin_until(executor, lambda: all(p.get_subscription_count() for p in pubs) and
                          node.pub_cloud.get_subscription_count() > 0)
        info = info_msg(frame.stamp_ns, frame.frame_id, k.width, k.height)
        info.k = [k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0]
        pubs[0].publish(info)
        assert spin_until(executor, lambda: node.stats.received['camera_info'] == 1)
        pubs[1].publish(image_msg(frame.color, 'rgb8', frame.color_stamp_ns, frame.frame_id))
        pubs[2].publish(image_msg(frame.depth.astype(np.float32), '32FC1', frame.stamp_ns,
                                  frame.frame_id))
        assert spin_until(executor, lambda: bool(clouds), timeout=30.0)
    finally:
        executor.shutdown()
        node.destroy_node()
        tester.destroy_node()
    points = convert.cloud_to_array(clouds[0])
    assert convert.stamp_to_ns(clouds[0].header.stamp) == frame.stamp_ns
    assert clouds[0].header.frame_id == frame.frame_id
    from endeff_ros.scoring import score_frame

    score = score_frame(convert.xyz(points), frame.gt)
    assert score.tp >= 3, (convert.xyz(points), frame.gt)


def test_debug_outputs_switch_at_runtime(harness):
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import Image, PointCloud2

    h = harness(publish_debug_bands=True)
    bands: list = []
    images: list = []
    h.tester.create_subscription(PointCloud2, 'debug/bands', bands.append, 10)
    h.tester.create_subscription(Image, 'debug/image', images.append, 10)
    assert spin_until(h.executor, lambda: h.node.pub_bands.get_subscription_count() > 0 and
                      h.node.pub_image.get_subscription_count() > 0)
    h.send(13_000_000_000)
    assert h.wait_clouds(1) and spin_until(h.executor, lambda: bool(bands))
    assert 'rgb' in convert.cloud_to_array(bands[0]).dtype.names and not images
    assert h.node.set_parameters([Parameter('publish_debug_image', value=True)])[0].successful
    h.send(13_100_000_000)
    assert h.wait_clouds(2) and spin_until(h.executor, lambda: bool(images))
    image = images[0]
    assert (image.encoding, image.width, image.height) == ('rgb8', W, H)
    assert convert.stamp_to_ns(image.header.stamp) == 13_100_000_000
    drawn = convert.color_image_to_array(image)
    assert (drawn != 90).any()  # the track was drawn over the uniform input colour


def _compressed(stamp_ns: int, frame_id: str, fmt_data: tuple[str, bytes]):
    from sensor_msgs.msg import CompressedImage

    fmt, data = fmt_data
    msg = CompressedImage(format=fmt, data=data)
    msg.header = convert.make_header(stamp_ns, frame_id)
    return msg


def _send_compressed(h: Harness, pubs: dict, stamp_ns: int, depth_m: float) -> None:
    from endeff_ros import image_codecs

    count = h.node.stats.received['camera_info']
    h.pub['info'].publish(info_msg(stamp_ns, FRAME_ID, W, H))
    assert spin_until(h.executor, lambda: h.node.stats.received['camera_info'] > count)
    rgb = np.full((H, W, 3), 90, np.uint8)
    pubs['color'].publish(_compressed(stamp_ns + 3_000_000, 'color_frame',
                                      image_codecs.encode_color(rgb, 'rgb8', 'jpeg')))
    mm = np.full((H, W), 3800, np.uint16)
    mm[5, 7] = round(depth_m * 1000)
    pubs['depth'].publish(_compressed(stamp_ns, FRAME_ID,
                                      image_codecs.encode_depth(mm, '16UC1')))


@pytest.mark.parametrize('transport', ['compressed', 'auto'])
def test_compressed_image_transport(harness, transport):
    """image_transport's compressed colour and compressedDepth topics feed the node when told
    to (``compressed``), or when only they have publishers (``auto``); the depth is decoded
    losslessly, so the end-effector lies where the raw image would put it."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CompressedImage

    h = harness(image_transport=transport)
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    pubs = {'color': h.tester.create_publisher(CompressedImage, 'color/image_raw/compressed',
                                               qos),
            'depth': h.tester.create_publisher(CompressedImage,
                                               'depth/image_raw/compressedDepth', qos)}
    # ``auto`` switches once it sees that only the compressed topics have publishers.
    assert spin_until(h.executor, lambda: all(p.get_subscription_count() > 0
                                              for p in pubs.values())), 'no subscription'
    for k in range(3):
        _send_compressed(h, pubs, 1_000_000_000 + k * 33_333_333, depth_m=1.2)
    assert h.wait_clouds(1), h.node.snapshot()
    points = convert.cloud_to_array(h.clouds[-1])
    assert len(points) == 1 and points['z'][0] == pytest.approx(1.2, abs=1e-3)
    assert h.node.stats.bad_input == 0


def test_bad_image_transport_is_refused(ros_context):
    from rclpy.parameter import Parameter

    from endeff_ros.ros.node import EndeffNode

    with pytest.raises(ParameterError, match='image_transport'):
        EndeffNode(tracker_factory=FakeTracker, namespace='/bad_transport',
                   parameter_overrides=[Parameter('image_transport', value='theora')])


def test_lost_colour_images_do_not_cost_depth_frames(harness):
    """1 colour image in 4 lost: every depth image still gets its cloud, without waiting
    for color_timeout (a newer colour image shows the loss)."""
    h = harness(color_timeout=10.0)  # longer than wait_clouds waits: the timeout cannot help
    stamps = [13_000_000_000 + k * 33_333_333 for k in range(8)]
    for k, stamp in enumerate(stamps):
        lost = k % 4 == 1
        h.send(stamp, color=not lost, info=k == 0)
        # A frame with colour is answered at once (after the lost one before it, if any); a
        # frame whose colour is lost when the next colour image arrives.
        assert h.wait_clouds(k if lost else k + 1), (k, h.node.snapshot())
    got = [convert.stamp_to_ns(c.header.stamp) for c in h.clouds]
    assert got == stamps[:len(got)] and len(got) >= 7, (got, h.node.snapshot())
    assert h.node.stats.colorless == 2 and h.node.stats.warnings.get('color_lost') == 2


def test_one_stamp_far_ahead_does_not_reset(harness):
    h = harness()
    h.send(14_000_000_000)
    assert h.wait_clouds(1)
    h.send(14_000_000_000 + 86_400 * 10**9, info=False)  # one set stamped a day ahead
    h.send(14_033_333_333, info=False)
    assert h.wait_clouds(2)
    assert h.tracker.resets == 0 and h.node.stats.quarantined >= 1
    assert 'stamp_ahead' in h.node.stats.warnings
    assert convert.stamp_to_ns(h.clouds[1].header.stamp) == 14_033_333_333


def test_tiny_image_is_bad_input_and_keeps_the_tracks(harness):
    h = harness()
    h.send(15_000_000_000)
    assert h.wait_clouds(1)
    frames = len(h.tracker.frames)
    h.pub['info'].publish(info_msg(15_033_333_333, FRAME_ID, 1, 1))
    h.pub['depth'].publish(image_msg(np.full((1, 1), 1500, np.uint16), '16UC1',
                                     15_033_333_333, FRAME_ID))
    h.pub['color'].publish(image_msg(np.zeros((1, 1, 3), np.uint8), 'rgb8', 15_033_333_333,
                                     'color_frame'))
    assert spin_until(h.executor, lambda: h.node.stats.bad_input == 1)
    assert len(h.tracker.frames) == frames  # the tracker never saw it
    assert 'too small' in h.node.stats.last_warning


def test_empty_frame_id_is_warned_about(harness):
    h = harness()
    count = h.node.stats.received['camera_info']
    h.pub['info'].publish(info_msg(16_000_000_000, '', W, H))
    assert spin_until(h.executor, lambda: h.node.stats.received['camera_info'] > count)
    h.pub['color'].publish(image_msg(np.zeros((H, W, 3), np.uint8), 'rgb8', 16_000_000_000, ''))
    h.pub['depth'].publish(_depth_image(16_000_000_000, frame_id=''))
    assert h.wait_clouds(1)
    assert h.node.stats.warnings.get('empty_frame_id') == 1 and h.clouds[0].header.frame_id == ''


class EarlyTracker(FakeTracker):
    """A fake tracker whose Sections 3-4 may run early: records the frames it estimated."""

    estimate_wants_color = True  # as a real tracker's while its background learns

    def __init__(self, params: EndeffParams) -> None:
        super().__init__(params)
        self.estimated: list[int] = []

    def estimate(self, frame: RGBDFrame) -> FrameEstimate:
        self.estimated.append(frame.stamp_ns)
        return FakeTracker.update(self, frame).estimate  # not an update the node made


def test_no_early_estimate_while_the_tracker_wants_the_colour(ros_context):
    """The worker runs a depth image's Sections 3-4 before its colour partner arrives only
    when the tracker does not want the colour first (its background is learning: the
    frame's own colour motion decides, as in ``endeff process``)."""
    from endeff_ros.ros.node import EndeffNode

    node = EndeffNode(tracker_factory=EarlyTracker, namespace='/early')
    try:
        def prepare(stamp: int) -> None:
            mm = np.full((H, W), 1500, np.uint16)
            node._prepare(image_msg(mm, '16UC1', stamp, FRAME_ID),
                          info_msg(stamp, FRAME_ID, W, H))

        prepare(1_000_000_000)
        assert node.tracker.estimated == []
        node.tracker.estimate_wants_color = False
        prepare(2_000_000_000)
        assert node.tracker.estimated == [2_000_000_000]
    finally:
        node.destroy_node()


class FlowTracker(EarlyTracker):
    """An early fake tracker that also computes its optical flow apart (as the real one
    does): records each image it flowed (its pixel sum and the camera info's width) and the
    flow each update received; its early estimate waits (up to 10 s) for ``hold`` to be set,
    so that a test can deliver the colour image while the worker is busy with the depth
    image."""

    estimate_wants_color = False

    def __init__(self, params: EndeffParams) -> None:
        super().__init__(params)
        self.flowed: list[tuple[int, int]] = []  # (image sum, width): which image, which info
        self.flows_used: list[object] = []
        self.hold = threading.Event()
        self.hold.set()
        self.estimating = threading.Event()

    def flow(self, color: np.ndarray, intrinsics) -> object:
        self.flowed.append((int(color.sum()), intrinsics.width))
        return ('flow', len(self.flowed))

    def estimate(self, frame: RGBDFrame) -> FrameEstimate:
        self.estimating.set()
        self.hold.wait(10.0)
        return super().estimate(frame)

    def update(self, frame: RGBDFrame, estimate: FrameEstimate | None = None,
               flow: object = None) -> TrackerResult:
        self.flows_used.append(flow)
        return super().update(frame)


def test_a_colour_image_before_its_depth_gets_its_flow_early(harness):
    """A colour image that arrives first has its optical flow computed by the worker while
    the depth image is awaited, and the set's update receives exactly that flow."""
    h = harness(tracker_factory=FlowTracker)
    stamp = 20_000_000_000
    h.pub['info'].publish(info_msg(stamp, FRAME_ID, W, H))
    assert spin_until(h.executor, lambda: h.node.stats.received['camera_info'] == 1)
    h.pub['color'].publish(_colour_image(stamp + 3_000_000, 7))
    assert spin_until(h.executor, lambda: bool(h.tracker.flowed))
    h.pub['depth'].publish(_depth_image(stamp))
    assert h.wait_clouds(1)
    assert h.tracker.flowed == [(7 * H * W * 3, W)]
    assert h.tracker.flows_used == [('flow', 1)]
    assert h.node.stats.prepared_flow == 1 and h.node.stats.flow_alongside == 0


def test_a_colour_image_during_its_depths_estimate_gets_its_flow_alongside(harness):
    """A colour image that arrives while the worker runs the early Sections 3-4 of its depth
    partner has its flow computed at once in the subscription callback (on another core);
    the set uses both early results."""
    h = harness(tracker_factory=FlowTracker)
    stamp = 21_000_000_000
    h.pub['info'].publish(info_msg(stamp, FRAME_ID, W, H))
    assert spin_until(h.executor, lambda: h.node.stats.received['camera_info'] == 1)
    h.tracker.hold.clear()
    h.pub['depth'].publish(_depth_image(stamp))
    assert spin_until(h.executor, h.tracker.estimating.is_set)
    h.pub['color'].publish(_colour_image(stamp + 3_000_000, 9))
    assert spin_until(h.executor, lambda: bool(h.tracker.flowed))
    assert h.tracker.estimated == []  # the estimate was still waiting: flow alongside it
    h.tracker.hold.set()
    assert h.wait_clouds(1)
    assert h.tracker.estimated == [stamp]
    assert h.tracker.flows_used == [('flow', 1)]
    assert h.node.stats.flow_alongside == 1
    assert h.node.stats.prepared == 1 and h.node.stats.prepared_flow == 1
