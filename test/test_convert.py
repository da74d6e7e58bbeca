"""Tests of endeff_ros.ros.convert with rclpy messages and rosbags-deserialised messages."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import rosbags.typesys as rosbags_typesys
import sensor_msgs.msg as sensor_msgs

from endeff_ros.core.errors import InputError
from endeff_ros.core.types import Intrinsics, Track
from endeff_ros.ros import convert


@pytest.fixture(scope='module')
def typestore():
    return rosbags_typesys.get_typestore(rosbags_typesys.Stores.ROS2_JAZZY)


def rclpy_image(array: np.ndarray, encoding: str, *, pad: int = 0, bigendian: bool = False,
                stamp_ns: int = 12_345_000_000_789, frame_id: str = 'cam') -> object:
    """An rclpy Image holding ``array`` (H, W[, C]) with ``pad`` bytes of padding per row."""
    import array as pyarray

    h, w = array.shape[:2]
    a = array.astype(array.dtype.newbyteorder('>' if bigendian else '<'))
    rows = a.reshape(h, -1).view(np.uint8).reshape(h, -1)
    rows = np.concatenate([rows, np.full((h, pad), 0xAB, np.uint8)], axis=1)
    msg = sensor_msgs.Image()
    msg.header = convert.make_header(stamp_ns, frame_id)
    msg.height, msg.width = h, w
    msg.encoding = encoding
    msg.is_bigendian = bigendian
    msg.step = rows.shape[1]
    msg.data = pyarray.array('B', rows.tobytes())
    return msg


def to_rosbags(msg: object, typestore, msgtype: str) -> object:
    """Serialise an rclpy message to CDR and deserialise it with the rosbags typestore."""
    return typestore.deserialize_cdr(convert.serialize(msg), msgtype)


@pytest.fixture(params=['rclpy', 'rosbags'])
def flavour(request, typestore):
    """Turns an rclpy message into the message flavour under test."""
    if request.param == 'rclpy':
        return lambda msg, msgtype: msg
    return lambda msg, msgtype: to_rosbags(msg, typestore, msgtype)


IMAGE = 'sensor_msgs/msg/Image'
INFO = 'sensor_msgs/msg/CameraInfo'
CLOUD = 'sensor_msgs/msg/PointCloud2'


def test_module_does_not_import_rclpy():
    code = ('import sys; import endeff_ros.ros.convert; '
            'sys.exit(1 if "rclpy" in sys.modules else 0)')
    assert subprocess.run([sys.executable, '-c', code], check=False).returncode == 0


def test_stamp_round_trip():
    header = convert.make_header(1_700_000_000_123_456_789, 'f')
    assert header.stamp.sec == 1_700_000_000 and header.stamp.nanosec == 123_456_789
    assert convert.stamp_to_ns(header.stamp) == 1_700_000_000_123_456_789


@pytest.mark.parametrize('pad', [0, 6])
@pytest.mark.parametrize('bigendian', [False, True])
def test_depth_16uc1(flavour, pad, bigendian):
    rng = np.random.default_rng(0)
    mm = rng.integers(0, 5000, size=(7, 5)).astype(np.uint16)
    mm[0, 0] = 0
    msg = flavour(rclpy_image(mm, '16UC1', pad=pad, bigendian=bigendian), IMAGE)
    depth = convert.depth_image_to_array(msg)
    assert depth.dtype == np.float32 and depth.shape == (7, 5)
    valid = mm > 0
    np.testing.assert_allclose(depth[valid], mm[valid] / 1000.0, rtol=1e-6)
    assert np.all(np.isnan(depth[~valid]))


@pytest.mark.parametrize('pad', [0, 4])
@pytest.mark.parametrize('bigendian', [False, True])
def test_depth_32fc1(flavour, pad, bigendian):
    m = np.array([[1.5, 0.0, np.nan], [2.25, -1.0, np.inf]], np.float32)
    msg = flavour(rclpy_image(m, '32FC1', pad=pad, bigendian=bigendian), IMAGE)
    depth = convert.depth_image_to_array(msg)
    assert depth[0, 0] == np.float32(1.5) and depth[1, 0] == np.float32(2.25)
    assert np.isnan(depth[0, 1:]).all() and np.isnan(depth[1, 1:]).all()


@pytest.mark.parametrize('encoding', ['mono16', '8UC1', 'rgb8', ''])
def test_depth_bad_encoding_names_it(encoding):
    msg = rclpy_image(np.zeros((2, 2), np.uint16), encoding)
    with pytest.raises(InputError, match=repr(encoding).replace('(', r'\(')):
        convert.depth_image_to_array(msg)


def test_depth_short_data_is_input_error():
    msg = rclpy_image(np.zeros((4, 4), np.uint16), '16UC1')
    msg.height = 8
    with pytest.raises(InputError, match='bytes'):
        convert.depth_image_to_array(msg)
    msg = rclpy_image(np.zeros((4, 4), np.uint16), '16UC1')
    msg.step = 3
    with pytest.raises(InputError, match='step'):
        convert.depth_image_to_array(msg)


@pytest.mark.parametrize('encoding', ['rgb8', 'bgr8', 'rgba8', 'bgra8', 'mono8'])
@pytest.mark.parametrize('pad', [0, 3])
def test_color_encodings(flavour, encoding, pad):
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 256, size=(4, 6, 3)).astype(np.uint8)
    if encoding == 'mono8':
        raw, want = rgb[:, :, 0], np.repeat(rgb[:, :, :1], 3, axis=2)
    else:
        raw = rgb[:, :, ::-1] if encoding.startswith('bgr') else rgb
        if encoding.endswith('a8'):
            raw = np.concatenate([raw, np.full((4, 6, 1), 7, np.uint8)], axis=2)
        want = rgb
    msg = flavour(rclpy_image(np.ascontiguousarray(raw), encoding, pad=pad), IMAGE)
    out = convert.color_image_to_array(msg)
    assert out.dtype == np.uint8 and out.shape == (4, 6, 3)
    np.testing.assert_array_equal(out, want)


def test_color_bad_encoding():
    with pytest.raises(InputError, match='yuv422'):
        convert.color_image_to_array(rclpy_image(np.zeros((2, 2, 2), np.uint8), 'yuv422'))


def camera_info(fx=500.0, fy=510.0, cx=320.0, cy=240.0, w=640, h=480):
    msg = sensor_msgs.CameraInfo()
    msg.width, msg.height = w, h
    msg.k = [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]
    return msg


def test_camera_info(flavour):
    intr = convert.camera_info_to_intrinsics(flavour(camera_info(), INFO))
    assert intr == Intrinsics(500.0, 510.0, 320.0, 240.0, 640, 480)


def test_camera_info_zero_k(flavour):
    with pytest.raises(InputError, match='calibrated'):
        convert.camera_info_to_intrinsics(flavour(camera_info(0.0, 0.0, 0.0, 0.0), INFO))


def test_frame_from_messages(flavour):
    depth = flavour(rclpy_image(np.full((4, 6), 1200, np.uint16), '16UC1',
                                stamp_ns=5_000_000_123, frame_id='depth_optical'), IMAGE)
    color = flavour(rclpy_image(np.zeros((4, 6, 3), np.uint8), 'bgr8', stamp_ns=5_000_900_000,
                                frame_id='color_optical'), IMAGE)
    info = flavour(camera_info(w=6, h=4), INFO)
    frame = convert.frame_from_messages(color, depth, info)
    assert frame.stamp_ns == 5_000_000_123 and frame.frame_id == 'depth_optical'
    assert frame.color is not None and frame.color.shape == (4, 6, 3)
    np.testing.assert_allclose(frame.depth, 1.2, rtol=1e-6)
    assert convert.frame_from_messages(None, depth, info).color is None


def test_frame_size_mismatches():
    depth = rclpy_image(np.full((4, 6), 1200, np.uint16), '16UC1')
    with pytest.raises(InputError, match='camera info'):
        convert.frame_from_messages(None, depth, camera_info(w=640, h=480))
    color = rclpy_image(np.zeros((5, 6, 3), np.uint8), 'rgb8')
    with pytest.raises(InputError, match='colour'):
        convert.frame_from_messages(color, depth, camera_info(w=6, h=4))
    with pytest.raises(InputError, match='camera info'):
        convert.frame_from_messages(None, depth, None)


def make_tracks() -> list[Track]:
    return [
        Track(id=3, entity=0, position=np.array([0.1, -0.2, 2.0]), geodesic=0.9,
              confidence=0.75, state=Track.DETECTED, age=4,
              path=np.array([[0.1, -0.2, 2.0], [0.05, 0.0, 2.1], [0.0, 0.1, 2.2]]),
              velocity=np.array([0.5, -0.25, 0.0]), kind=Track.KIND_HAND),
        Track(id=7, entity=1, position=np.array([-0.5, 0.4, 3.0]), geodesic=1.2,
              confidence=0.25, state=Track.PREDICTED, age=1),
    ]


def test_endeff_fields_are_packed():
    assert convert.ENDEFF_DTYPE.itemsize == 4 * 10 + 2
    names = [f[0] for f in convert.ENDEFF_FIELDS]
    assert names == ['x', 'y', 'z', 'id', 'entity', 'geodesic', 'confidence', 'vx', 'vy', 'vz',
                     'state', 'kind']
    types = dict((f[0], f[2]) for f in convert.ENDEFF_FIELDS)
    assert types['state'] == types['kind'] == convert.UINT8
    assert all(offset % 4 == 0 for _, offset, dtype, _ in convert.ENDEFF_FIELDS
               if dtype != convert.UINT8)


def test_tracks_cloud_round_trip(flavour):
    header = convert.make_header(42_000_000_017, 'camera_depth_optical_frame')
    msg = convert.tracks_to_cloud(header, make_tracks())
    assert msg.height == 1 and msg.width == 2 and msg.point_step == 42
    assert msg.row_step == 84 and len(msg.data) == 84
    assert convert.stamp_to_ns(msg.header.stamp) == 42_000_000_017
    assert msg.header.frame_id == 'camera_depth_optical_frame'
    back = convert.cloud_to_array(flavour(msg, CLOUD))
    np.testing.assert_array_equal(back['id'], [3, 7])
    np.testing.assert_array_equal(back['entity'], [0, 1])
    np.testing.assert_array_equal(back['state'], [0, 1])
    np.testing.assert_allclose(convert.xyz(back), [[0.1, -0.2, 2.0], [-0.5, 0.4, 3.0]],
                               rtol=1e-6)
    np.testing.assert_allclose(back['confidence'], [0.75, 0.25])
    np.testing.assert_allclose(np.stack([back['vx'], back['vy'], back['vz']], axis=1),
                               [[0.5, -0.25, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(back['kind'], [2, 0])


def test_empty_cloud(flavour):
    msg = convert.tracks_to_cloud(convert.make_header(1, 'f'), [])
    assert msg.width == 0 and msg.height == 1 and len(msg.data) == 0
    assert [f.name for f in msg.fields][:3] == ['x', 'y', 'z']
    back = convert.cloud_to_array(flavour(msg, CLOUD))
    assert back.shape == (0,) and 'id' in back.dtype.names


def test_cloud_to_array_foreign_layout(flavour):
    """Ground truth written by someone else: padded points, organised, big-endian."""
    import array as pyarray

    dtype = np.dtype({'names': ['x', 'y', 'z', 'id'], 'formats': ['>f4', '>f4', '>f4', '>u4'],
                      'offsets': [0, 4, 8, 16], 'itemsize': 24})
    pts = np.zeros((2, 3), dtype=dtype)
    pts['x'] = np.arange(6).reshape(2, 3)
    pts['id'] = np.arange(6).reshape(2, 3) + 10
    rows = np.concatenate([pts.view(np.uint8).reshape(2, -1), np.zeros((2, 8), np.uint8)], 1)
    msg = sensor_msgs.PointCloud2()
    msg.height, msg.width = 2, 3
    msg.fields = [sensor_msgs.PointField(name=n, offset=o, datatype=d, count=1)
                  for n, o, d in [('x', 0, 7), ('y', 4, 7), ('z', 8, 7), ('id', 16, 6)]]
    msg.is_bigendian = True
    msg.point_step = 24
    msg.row_step = 24 * 3 + 8
    msg.data = pyarray.array('B', rows.tobytes())
    back = convert.cloud_to_array(flavour(msg, CLOUD))
    np.testing.assert_array_equal(back['x'], np.arange(6))
    np.testing.assert_array_equal(back['id'], np.arange(6) + 10)


def test_cloud_too_short_is_input_error():
    msg = convert.tracks_to_cloud(convert.make_header(1, 'f'), make_tracks())
    msg.width = 3
    with pytest.raises(InputError):
        convert.cloud_to_array(msg)


class _Entity:
    def __init__(self, entity, root):
        self.entity, self.root, self.candidates = entity, np.asarray(root), []


class _Estimate:
    def __init__(self):
        self.entities = [_Entity(0, [0.0, 0.0, 2.5]), _Entity(1, [0.3, 0.0, 3.5])]
        self.points = np.array([[0, 0, 2.0], [0, 0.1, 2.0], [0.1, 0.1, 2.0]])
        self.subband = np.array([0, 1, -1])


class _Result:
    def __init__(self, tracks):
        self.tracks, self.estimate = tracks, _Estimate()


def test_markers_match_cloud():
    from visualization_msgs.msg import Marker

    tracks = make_tracks()
    header = convert.make_header(99, 'cam')
    markers = convert.result_to_markers(header, _Result(tracks), lifetime_s=0.25).markers
    assert markers[0].action == Marker.DELETEALL
    assert all(m.header.frame_id == 'cam' and convert.stamp_to_ns(m.header.stamp) == 99
               for m in markers)
    spheres = [m for m in markers if m.ns == convert.NS_EFFECTOR]
    cloud = convert.cloud_to_array(convert.tracks_to_cloud(header, tracks))
    assert [m.id for m in spheres] == list(cloud['id'])
    pos = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                    for m in spheres])
    np.testing.assert_allclose(pos, convert.xyz(cloud), atol=1e-6)
    labels = [m for m in markers if m.ns == convert.NS_LABEL]
    assert [m.type for m in labels] == [Marker.TEXT_VIEW_FACING] * 2
    # The kind first, then the id; a prediction says so.
    assert [m.text for m in labels] == ['hand 3', 'other 7 (predicted)']
    paths = [m for m in markers if m.ns == convert.NS_PATH]
    assert len(paths) == 1 and paths[0].type == Marker.LINE_STRIP and len(paths[0].points) == 3
    roots = [m for m in markers if m.ns == convert.NS_ROOT]
    assert [m.pose.position.z for m in roots] == [2.5, 3.5]
    added = [m for m in markers if m.action == Marker.ADD]
    assert all(m.lifetime.sec == 0 and m.lifetime.nanosec == 250_000_000 for m in added)


def test_bands_cloud_colours():
    msg = convert.bands_to_cloud(convert.make_header(1, 'f'), _Estimate())
    back = convert.cloud_to_array(msg)
    assert back.shape == (3,)
    packed = back['rgb'].view(np.uint32)
    assert packed[0] != packed[1]
    assert packed[2] == (128 << 16 | 128 << 8 | 128)


def test_draw_tracks_and_image_msg(flavour):
    intr = Intrinsics(500.0, 500.0, 32.0, 24.0, 64, 48)
    img = np.zeros((48, 64, 3), np.uint8)
    out = convert.draw_tracks(img, intr, make_tracks())
    assert out.shape == img.shape and out.any() and not img.any()
    msg = convert.array_to_image_msg(convert.make_header(5, 'f'), out)
    assert msg.encoding == 'rgb8' and msg.step == 64 * 3
    np.testing.assert_array_equal(convert.color_image_to_array(flavour(msg, IMAGE)), out)
