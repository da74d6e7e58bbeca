"""Conversion between ROS messages and numpy, in the style of ``sensor_msgs_py.point_cloud2``.

Input functions are duck-typed: they read rclpy messages and messages deserialised by
``rosbags`` alike (same attribute names; ``data`` is ``array.array``/``bytes`` for rclpy and a
numpy ``uint8`` array for rosbags). Nothing here imports rclpy at module import time; the output
builders import the message classes when they are called, so that the node and the offline tools
(``endeff process``) build identical messages.

Depth follows ``depth_image_proc``: ``16UC1`` is millimetres, ``32FC1`` is metres, 0 (and NaN)
means no reading; anything else is an :class:`~endeff_ros.core.errors.InputError`.
``sensor_msgs/CompressedImage`` (image_transport's ``compressed`` and ``compressedDepth``) is
decoded by :mod:`endeff_ros.image_codecs`; :func:`frame_from_messages` takes raw and compressed
messages alike.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any

import numpy as np

from endeff_ros import image_codecs
from endeff_ros.core.errors import InputError
from endeff_ros.core.kinds import kind_name
from endeff_ros.core.types import Intrinsics, RGBDFrame, Track

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy.typing as npt

    from endeff_ros.core.single_frame import FrameEstimate
    from endeff_ros.core.tracker import TrackerResult

# sensor_msgs/PointField datatypes
INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = range(1, 9)

_POINTFIELD_TO_NUMPY: dict[int, str] = {
    INT8: 'i1', UINT8: 'u1', INT16: 'i2', UINT16: 'u2', INT32: 'i4', UINT32: 'u4',
    FLOAT32: 'f4', FLOAT64: 'f8'}
_NUMPY_TO_POINTFIELD: dict[str, int] = {v: k for k, v in _POINTFIELD_TO_NUMPY.items()}

#: One row of the ``end_effectors`` cloud (packed; ``point_step`` = ``ENDEFF_DTYPE.itemsize``,
#: 42 bytes). Every 4-byte field lies at a multiple of 4, the two bytes last, so a consumer
#: that reads fields by offset reads aligned floats. docs/output.md is the contract.
ENDEFF_DTYPE = np.dtype([
    ('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('id', '<u4'), ('entity', '<u4'),
    ('geodesic', '<f4'), ('confidence', '<f4'), ('vx', '<f4'), ('vy', '<f4'), ('vz', '<f4'),
    ('state', 'u1'), ('kind', 'u1')])

#: (name, offset, PointField datatype, count) of :data:`ENDEFF_DTYPE`.
ENDEFF_FIELDS: tuple[tuple[str, int, int, int], ...] = tuple(
    (name, ENDEFF_DTYPE.fields[name][1], _NUMPY_TO_POINTFIELD[ENDEFF_DTYPE[name].str[1:]], 1)
    for name in ENDEFF_DTYPE.names)

#: x, y, z and a PCL-style packed ``rgb`` (float32 carrying 0x00RRGGBB) for ``debug/bands``.
BANDS_DTYPE = np.dtype([('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('rgb', '<f4')])

_DEPTH_ENCODINGS = {'16UC1': ('u2', 1e-3), '32FC1': ('f4', 1.0)}
# encoding -> (channels, channel order to take for RGB)
_COLOR_ENCODINGS: dict[str, tuple[int, tuple[int, ...]]] = {
    'rgb8': (3, (0, 1, 2)), 'bgr8': (3, (2, 1, 0)), 'rgba8': (4, (0, 1, 2)),
    'bgra8': (4, (2, 1, 0)), 'mono8': (1, (0, 0, 0))}


# --------------------------------------------------------------------------------------------
# Inputs (duck-typed, no rclpy)
# --------------------------------------------------------------------------------------------

def stamp_to_ns(stamp: Any) -> int:
    """``builtin_interfaces/Time`` (``sec``, ``nanosec``) -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_sec_nanosec(stamp_ns: int) -> tuple[int, int]:
    """Integer nanoseconds -> (``sec``, ``nanosec``) as in ``builtin_interfaces/Time``."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return sec, nanosec


_raw_bytes = image_codecs.as_uint8


def _image_pixels(msg: Any, base: str, channels: int) -> npt.NDArray[Any]:
    """Image payload as (H, W, channels) of ``base`` dtype, honouring ``step`` and endianness."""
    dtype = np.dtype(base).newbyteorder('>' if msg.is_bigendian else '<')
    h, w = int(msg.height), int(msg.width)
    row_bytes = w * channels * dtype.itemsize
    step = int(msg.step)
    raw = _raw_bytes(msg.data)
    if h <= 0 or w <= 0:
        msg_ = f'{msg.encoding} image has an empty size {w}x{h}'
        raise InputError(msg_)
    if step < row_bytes:
        msg_ = (f'{msg.encoding} image: step {step} is smaller than width {w} x '
                f'{channels * dtype.itemsize} bytes')
        raise InputError(msg_)
    if raw.size < step * (h - 1) + row_bytes:
        msg_ = (f'{msg.encoding} image {w}x{h} (step {step}) needs {step * h} bytes of data, '
                f'got {raw.size}')
        raise InputError(msg_)
    if raw.size < step * h:  # tolerate a missing tail of padding on the last row
        raw = np.concatenate([raw, np.zeros(step * h - raw.size, np.uint8)])
    rows = raw[:step * h].reshape(h, step)[:, :row_bytes]
    return np.ascontiguousarray(rows).view(dtype).reshape(h, w, channels)


def depth_image_to_array(msg: Any) -> npt.NDArray[np.float32]:
    """``sensor_msgs/Image`` depth -> (H, W) float32 metres, NaN where there is no reading.

    ``16UC1`` is read as millimetres and ``32FC1`` as metres; zero, negative and non-finite
    values become NaN. Any other encoding raises :class:`InputError` naming it.
    """
    encoding = str(msg.encoding)
    if encoding not in _DEPTH_ENCODINGS:
        msg_ = (f'unsupported depth encoding {encoding!r} (expected 16UC1 in millimetres or '
                f'32FC1 in metres)')
        raise InputError(msg_)
    base, _ = _DEPTH_ENCODINGS[encoding]
    return image_codecs.depth_to_metres(_image_pixels(msg, base, 1)[:, :, 0], encoding)


def color_image_to_array(msg: Any) -> npt.NDArray[np.uint8]:
    """``sensor_msgs/Image`` colour (rgb8, bgr8, rgba8, bgra8, mono8) -> (H, W, 3) uint8 RGB."""
    encoding = str(msg.encoding)
    if encoding not in _COLOR_ENCODINGS:
        msg_ = (f'unsupported colour encoding {encoding!r} (expected one of '
                f'{", ".join(_COLOR_ENCODINGS)})')
        raise InputError(msg_)
    channels, order = _COLOR_ENCODINGS[encoding]
    pixels = _image_pixels(msg, 'u1', channels)
    if tuple(order) == (0, 1, 2) and channels == 3:
        return pixels  # rgb8: already RGB, no copy (3 ms for 640x480 with the fancy index)
    out = np.empty(pixels.shape[:2] + (3,), dtype=np.uint8)
    for k, src in enumerate(order):  # three plane copies: 4x cheaper than fancy indexing
        out[:, :, k] = pixels[:, :, src]
    return out


def is_compressed(msg: Any) -> bool:
    """True for a ``sensor_msgs/CompressedImage`` (``format``, no ``encoding``)."""
    return hasattr(msg, 'format') and not hasattr(msg, 'encoding')


def compressed_color_to_array(msg: Any) -> npt.NDArray[np.uint8]:
    """``sensor_msgs/CompressedImage`` colour (image_transport ``compressed``: JPEG or PNG,
    rgb8/bgr8/rgba8/bgra8/mono8) -> (H, W, 3) uint8 RGB."""
    return image_codecs.decode_color(str(msg.format), msg.data)


def compressed_depth_to_array(msg: Any) -> npt.NDArray[np.float32]:
    """``sensor_msgs/CompressedImage`` depth (``compressedDepth`` PNG of 16UC1 or 32FC1, or a
    ``compressed`` 16UC1 PNG) -> (H, W) float32 metres, NaN where there is no reading."""
    return image_codecs.decode_depth(str(msg.format), msg.data)


def any_color_to_array(msg: Any) -> npt.NDArray[np.uint8]:
    """Raw or compressed colour image -> (H, W, 3) uint8 RGB."""
    if is_compressed(msg):
        return compressed_color_to_array(msg)
    return color_image_to_array(msg)


def any_depth_to_array(msg: Any) -> npt.NDArray[np.float32]:
    """Raw or compressed depth image -> (H, W) float32 metres, NaN where there is no reading."""
    if is_compressed(msg):
        return compressed_depth_to_array(msg)
    return depth_image_to_array(msg)


def camera_info_to_intrinsics(msg: Any) -> Intrinsics:
    """``sensor_msgs/CameraInfo`` -> :class:`Intrinsics` (InputError for zero/invalid K)."""
    k = getattr(msg, 'k', None)
    if k is None:
        k = msg.K  # ROS 1 style spelling, e.g. converted bags
    return Intrinsics.from_k(np.asarray(k, dtype=np.float64), int(msg.width), int(msg.height))


def frame_from_messages(color_msg: Any | None, depth_msg: Any, info_msg: Any, *,
                        depth: npt.NDArray[np.float32] | None = None,
                        color: npt.NDArray[np.uint8] | None = None) -> RGBDFrame:
    """One synchronised set -> :class:`RGBDFrame` stamped and framed by the depth header.

    Colour and depth may each be ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage``.
    ``depth`` / ``color``, when given, are those messages already decoded
    (:func:`any_depth_to_array`, :func:`any_color_to_array`, e.g. on a reader thread).
    Raises :class:`InputError` for unknown encodings, unusable intrinsics or size mismatches.
    """
    if info_msg is None:
        msg_ = 'no camera info received yet for the depth image'
        raise InputError(msg_)
    if depth is None:
        depth = any_depth_to_array(depth_msg)
    intrinsics = camera_info_to_intrinsics(info_msg)
    if color is None and color_msg is not None:
        color = any_color_to_array(color_msg)
    return RGBDFrame(stamp_ns=stamp_to_ns(depth_msg.header.stamp),
                     frame_id=str(depth_msg.header.frame_id), depth=depth,
                     intrinsics=intrinsics, color=color)


def cloud_dtype(msg: Any) -> np.dtype:
    """The structured numpy dtype of a ``PointCloud2``'s points (with ``point_step`` padding)."""
    order = '>' if msg.is_bigendian else '<'
    names, formats, offsets = [], [], []
    for f in msg.fields:
        if int(f.datatype) not in _POINTFIELD_TO_NUMPY:
            msg_ = f'PointCloud2 field {f.name!r} has unknown datatype {f.datatype}'
            raise InputError(msg_)
        count = int(getattr(f, 'count', 1))
        if count <= 0:
            continue
        base = np.dtype(_POINTFIELD_TO_NUMPY[int(f.datatype)]).newbyteorder(order)
        names.append(str(f.name))
        formats.append(base if count == 1 else (base, (count,)))
        offsets.append(int(f.offset))
    return np.dtype({'names': names, 'formats': formats, 'offsets': offsets,
                     'itemsize': int(msg.point_step)})


def cloud_to_array(msg: Any) -> npt.NDArray[Any]:
    """Any ``PointCloud2`` -> flat (height * width,) structured array, one field per PointField.

    Honours ``point_step``/``row_step`` padding and ``is_bigendian``. Use e.g. ``a['x']``,
    ``a['id']``; :func:`xyz` stacks the coordinates.
    """
    dtype = cloud_dtype(msg)
    h, w = int(msg.height), int(msg.width)
    if h * w == 0:
        return np.zeros(0, dtype=dtype)
    row_bytes = w * dtype.itemsize
    row_step = int(msg.row_step) or row_bytes
    raw = _raw_bytes(msg.data)
    if row_step < row_bytes or raw.size < row_step * (h - 1) + row_bytes:
        msg_ = (f'PointCloud2 {w}x{h} with point_step {dtype.itemsize} and row_step {row_step} '
                f'does not fit its {raw.size} bytes of data')
        raise InputError(msg_)
    if raw.size < row_step * h:
        raw = np.concatenate([raw, np.zeros(row_step * h - raw.size, np.uint8)])
    rows = np.ascontiguousarray(raw[:row_step * h].reshape(h, row_step)[:, :row_bytes])
    return rows.view(dtype).reshape(-1)


def xyz(points: npt.NDArray[Any]) -> npt.NDArray[np.float64]:
    """(N,) structured array with x, y, z -> (N, 3) float64."""
    return np.stack([points['x'], points['y'], points['z']], axis=-1).astype(np.float64)


# --------------------------------------------------------------------------------------------
# Outputs (rclpy message classes imported lazily)
# --------------------------------------------------------------------------------------------

def make_header(stamp_ns: int, frame_id: str) -> Any:
    """A ``std_msgs/Header`` from integer nanoseconds and a frame id."""
    from std_msgs.msg import Header

    header = Header()
    header.stamp.sec, header.stamp.nanosec = ns_to_sec_nanosec(stamp_ns)
    header.frame_id = str(frame_id)
    return header


def _header(header: Any) -> Any:
    """Copy any header-like object (rclpy or rosbags) into a fresh rclpy ``Header``."""
    return make_header(stamp_to_ns(header.stamp), header.frame_id)


def _duration(seconds: float) -> Any:
    from builtin_interfaces.msg import Duration

    sec, nanosec = ns_to_sec_nanosec(round(max(0.0, seconds) * 1e9))
    return Duration(sec=sec, nanosec=nanosec)


def point_fields(dtype: np.dtype) -> list[Any]:
    """``sensor_msgs/PointField`` list describing a structured dtype (scalar fields only)."""
    from sensor_msgs.msg import PointField

    fields = []
    for name in dtype.names:
        sub, offset = dtype.fields[name][:2]
        base, count = (sub.base, int(np.prod(sub.shape))) if sub.shape else (sub, 1)
        fields.append(PointField(name=name, offset=int(offset),
                                 datatype=_NUMPY_TO_POINTFIELD[base.str[1:]], count=count))
    return fields


def create_cloud(header: Any, points: npt.NDArray[Any]) -> Any:
    """Unorganised ``PointCloud2`` (height 1) from a structured array; little-endian data."""
    import array

    from sensor_msgs.msg import PointCloud2

    points = np.ascontiguousarray(points.reshape(-1))
    if sys.byteorder != 'little' or any(
            points.dtype[n].byteorder == '>' for n in points.dtype.names):
        points = points.astype(points.dtype.newbyteorder('<'))
    msg = PointCloud2()
    msg.header = _header(header)
    msg.height = 1
    msg.width = int(points.shape[0])
    msg.fields = point_fields(points.dtype)
    msg.is_bigendian = False
    msg.point_step = int(points.dtype.itemsize)
    msg.row_step = msg.point_step * msg.width
    msg.data = array.array('B', points.tobytes())
    msg.is_dense = True
    return msg


def tracks_to_array(tracks: Sequence[Track]) -> npt.NDArray[Any]:
    """Tracks -> (N,) array of :data:`ENDEFF_DTYPE`."""
    out = np.zeros(len(tracks), dtype=ENDEFF_DTYPE)
    for i, t in enumerate(tracks):
        p = np.asarray(t.position, dtype=np.float64).reshape(3)
        v = np.asarray(t.velocity, dtype=np.float64).reshape(3)
        out[i] = (p[0], p[1], p[2], int(t.id), int(t.entity), float(t.geodesic),
                  float(t.confidence), v[0], v[1], v[2], int(t.state), int(t.kind))
    return out


def tracks_to_cloud(header: Any, tracks: Sequence[Track]) -> Any:
    """The ``end_effectors`` ``PointCloud2``: one row per track (empty cloud for no tracks)."""
    return create_cloud(header, tracks_to_array(tracks))


_PALETTE = np.array([
    [230, 25, 75], [60, 180, 75], [255, 225, 25], [0, 130, 200], [245, 130, 48],
    [145, 30, 180], [70, 240, 240], [240, 50, 230], [210, 245, 60], [250, 190, 212],
    [0, 128, 128], [220, 190, 255], [170, 110, 40], [255, 250, 200], [128, 0, 0],
    [170, 255, 195]], dtype=np.uint8)


def palette(index: int | npt.NDArray[np.integer]) -> npt.NDArray[np.uint8]:
    """Distinct RGB colour(s) for integer label(s); negative labels are grey."""
    idx = np.asarray(index)
    rgb = _PALETTE[np.mod(idx, len(_PALETTE))]
    return np.where((idx < 0)[..., None], np.uint8(128), rgb).astype(np.uint8)


def _color(rgb: npt.NDArray[np.uint8], alpha: float = 1.0) -> Any:
    from std_msgs.msg import ColorRGBA

    return ColorRGBA(r=float(rgb[0]) / 255.0, g=float(rgb[1]) / 255.0,
                     b=float(rgb[2]) / 255.0, a=float(alpha))


def _point(p: npt.ArrayLike) -> Any:
    from geometry_msgs.msg import Point

    x, y, z = (float(v) for v in np.asarray(p, dtype=np.float64).reshape(3))
    return Point(x=x, y=y, z=z)


#: Marker namespaces of :func:`result_to_markers`.
NS_EFFECTOR, NS_LABEL, NS_PATH, NS_ROOT = 'end_effectors', 'labels', 'paths', 'roots'


def marker_label(track: Track) -> str:
    """A track's marker text: its kind and id (``hand 7``, ``other 3`` for an end that is no
    known part of a person), `` (predicted)`` appended while no detection supports it. The
    kind comes first because it is what a person watching RViz looks for; the id tells two
    hands apart and follows one over time."""
    text = f'{kind_name(int(getattr(track, "kind", 0)))} {int(track.id)}'
    return text if int(track.state) == Track.DETECTED else f'{text} (predicted)'


def result_to_markers(header: Any, result: TrackerResult, lifetime_s: float = 0.2) -> Any:
    """``end_effectors/markers``: DELETEALL, then per track a sphere, a label and its path.

    Each track gets a SPHERE (namespace ``end_effectors``, marker id = track id), a
    TEXT_VIEW_FACING label (:func:`marker_label`: ``hand 7``) and a LINE_STRIP through
    ``track.path`` (sub-band centroids to the root); each entity gets a root sphere. Every
    marker carries ``header`` and a ``lifetime_s`` lifetime so that stale markers vanish when
    the node stops. ``result`` needs ``tracks`` and ``estimate`` (which may be None: no root
    markers).
    """
    from visualization_msgs.msg import Marker, MarkerArray

    header = _header(header)
    lifetime = _duration(lifetime_s)
    out = MarkerArray()
    clear = Marker()
    clear.header = header
    clear.action = Marker.DELETEALL
    out.markers.append(clear)

    def new(ns: str, ident: int, kind: int) -> Any:
        m = Marker()
        m.header = header
        m.ns = ns
        m.id = int(ident)
        m.type = kind
        m.action = Marker.ADD
        m.lifetime = lifetime
        m.pose.orientation.w = 1.0
        return m

    for t in result.tracks:
        rgb = palette(int(t.id))
        alpha = 1.0 if t.state == 0 else 0.4
        sphere = new(NS_EFFECTOR, t.id, Marker.SPHERE)
        sphere.pose.position = _point(t.position)
        sphere.scale.x = sphere.scale.y = sphere.scale.z = 0.08
        sphere.color = _color(rgb, alpha)
        out.markers.append(sphere)
        label = new(NS_LABEL, t.id, Marker.TEXT_VIEW_FACING)
        label.pose.position = _point(np.asarray(t.position, dtype=np.float64) +
                                     np.array([0.0, -0.08, 0.0]))
        label.scale.z = 0.06
        label.color = _color(np.array([255, 255, 255], np.uint8))
        label.text = marker_label(t)
        out.markers.append(label)
        path = np.asarray(t.path, dtype=np.float64).reshape(-1, 3)
        if path.shape[0] >= 2:
            line = new(NS_PATH, t.id, Marker.LINE_STRIP)
            line.scale.x = 0.01
            line.color = _color(rgb, 0.8)
            line.points = [_point(p) for p in path]
            out.markers.append(line)
    estimate = getattr(result, 'estimate', None)
    for e in (estimate.entities if estimate is not None else []):
        root = new(NS_ROOT, int(e.entity), Marker.SPHERE)
        root.pose.position = _point(e.root)
        root.scale.x = root.scale.y = root.scale.z = 0.1
        root.color = _color(np.array([255, 255, 255], np.uint8), 0.8)
        out.markers.append(root)
    return out


def _pack_rgb(rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.float32]:
    """(N, 3) uint8 -> (N,) float32 whose bits are 0x00RRGGBB (PCL/RViz ``rgb`` field)."""
    rgb = rgb.astype(np.uint32)
    packed = (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]
    return packed.astype('<u4').view('<f4')


def bands_to_array(estimate: FrameEstimate) -> npt.NDArray[Any]:
    """Foreground points coloured by sub-band -> (N,) array of :data:`BANDS_DTYPE`."""
    pts = np.asarray(estimate.points, dtype=np.float64).reshape(-1, 3)
    out = np.zeros(pts.shape[0], dtype=BANDS_DTYPE)
    out['x'], out['y'], out['z'] = pts[:, 0], pts[:, 1], pts[:, 2]
    labels = np.asarray(estimate.subband).reshape(-1)
    if labels.shape[0] == pts.shape[0]:
        out['rgb'] = _pack_rgb(palette(labels))
    return out


def bands_to_cloud(header: Any, estimate: FrameEstimate) -> Any:
    """``debug/bands``: the foreground cloud with x, y, z, rgb coloured by sub-band."""
    return create_cloud(header, bands_to_array(estimate))


def depth_to_rgb(depth: npt.NDArray[np.float32], max_m: float = 5.0) -> npt.NDArray[np.uint8]:
    """(H, W) metres -> (H, W, 3) grey image (near = bright, no reading = black)."""
    d = np.nan_to_num(np.asarray(depth, dtype=np.float32), nan=0.0)
    grey = np.where(d > 0, 255.0 * (1.0 - np.clip(d / max_m, 0.0, 1.0)), 0.0).astype(np.uint8)
    return np.repeat(grey[:, :, None], 3, axis=2)


def draw_tracks(color_rgb: npt.NDArray[np.uint8], intrinsics: Intrinsics,
                tracks: Sequence[Track]) -> npt.NDArray[np.uint8]:
    """Copy of ``color_rgb`` (H, W, 3) with each track's path, position, kind and id drawn on
    it (``hand 7``, as the markers' labels)."""
    import cv2

    img = np.ascontiguousarray(color_rgb, dtype=np.uint8).copy()
    for t in tracks:
        rgb = tuple(int(c) for c in palette(int(t.id)))
        path = np.asarray(t.path, dtype=np.float64).reshape(-1, 3)
        path = path[path[:, 2] > 0]
        if path.shape[0] >= 2:
            uv = np.round(intrinsics.project(path)).astype(np.int32)
            cv2.polylines(img, [uv.reshape(-1, 1, 2)], False, rgb, 1, cv2.LINE_AA)
        p = np.asarray(t.position, dtype=np.float64).reshape(1, 3)
        if p[0, 2] <= 0 or not np.all(np.isfinite(p)):
            continue
        u, v = (int(round(c)) for c in intrinsics.project(p)[0])
        cv2.circle(img, (u, v), 6, rgb, -1 if t.state == 0 else 2, cv2.LINE_AA)
        # The marker's label less its state, which the filled or hollow circle shows.
        text = f'{kind_name(int(getattr(t, "kind", 0)))} {int(t.id)}'
        for colour, thick in (((0, 0, 0), 3), (rgb, 1)):  # outlined: legible on any colour
            cv2.putText(img, text, (u + 8, v - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.5, colour,
                        thick, cv2.LINE_AA)
    return img


def array_to_image_msg(header: Any, image: npt.NDArray[np.uint8]) -> Any:
    """(H, W, 3) uint8 RGB -> ``sensor_msgs/Image`` rgb8; (H, W) uint8 -> mono8."""
    import array

    from sensor_msgs.msg import Image

    img = np.ascontiguousarray(image, dtype=np.uint8)
    if img.ndim == 2:
        encoding, channels = 'mono8', 1
    elif img.ndim == 3 and img.shape[2] == 3:
        encoding, channels = 'rgb8', 3
    else:
        msg_ = f'cannot publish an image of shape {img.shape} (need (H, W) or (H, W, 3))'
        raise InputError(msg_)
    msg = Image()
    msg.header = _header(header)
    msg.height, msg.width = int(img.shape[0]), int(img.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = False
    msg.step = msg.width * channels
    msg.data = array.array('B', img.tobytes())
    return msg


def serialize(msg: Any) -> bytes:
    """CDR bytes of an rclpy message (what ``rosbags.rosbag2.Writer.write`` takes)."""
    from rclpy.serialization import serialize_message

    return serialize_message(msg)
