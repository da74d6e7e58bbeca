"""Test helpers: a benchmark-bag writer independent of endeff_ros, and fake estimators.

The writer uses only ``rosbags`` (Writer + Jazzy typestore) and numpy, never endeff_ros code, so
bags it writes stand for bags "written by anyone" (spec: benchmark-bags.md). The scene is a
few blobs on a flat background; each blob's centre is a ground-truth end-effector moving fast
(about 0.15 m per frame), so matching ground truth to the wrong frame fails the 0.15 m threshold.

The fakes (:func:`fake_estimate_frame`, :class:`FakeTracker`) find the blobs by depth
thresholding and return real :class:`FrameEstimate` / :class:`TrackerResult` objects, so the
offline tools can be tested before, and independently of, the real algorithm core.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag2 import Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types

TOPICS = {'color': '/camera/color/image_raw', 'depth': '/camera/depth/image_raw',
          'info': '/camera/depth/camera_info', 'gt': '/ground_truth/end_effectors'}
REALSENSE = {'color': '/camera/camera/color/image_raw',
             'depth': '/camera/camera/aligned_depth_to_color/image_raw',
             'info': '/camera/camera/aligned_depth_to_color/camera_info',
             'gt': '/ground_truth/end_effectors'}
KINECT = {'color': '/rgb/image_raw', 'depth': '/depth_to_rgb/image_raw',
          'info': '/rgb/camera_info', 'gt': '/ground_truth/end_effectors'}

START_NS = 1_700_000_000_000_000_000
PERIOD_NS = 33_333_333
BACKGROUND_M = 3.5
FX = FY = 80.0
BLOB_PX = 3  # half size of a blob in pixels


@dataclass
class BagSpec:
    """What :func:`write_bag` writes; the defaults make a valid contract bag."""

    frames: int = 8
    width: int = 64
    height: int = 48
    storage: str = 'mcap'
    depth_encoding: str = '16UC1'
    color_encoding: str = 'rgb8'
    topics: dict[str, str] = field(default_factory=lambda: dict(TOPICS))
    gt_frames: set[int] | None = None  # None: every frame annotated
    drop_color: set[int] = field(default_factory=set)
    drop_depth: set[int] = field(default_factory=set)
    info_every: int = 1  # camera info every n-th frame (0: never)
    info_start: int = 0  # no camera info before this frame
    color_offset_ns: int = 4_000_000  # colour stamp = depth stamp + this (real drivers)
    log_delay_ns: int = 7_000_000  # log time = stamp + this; colour written after depth
    shuffle_log: bool = False  # write messages in a scrambled log order
    compression: str = ''  # '', 'message' or 'file'
    frame_id: str = 'camera_color_optical_frame'
    n_blobs: int = 3
    fx: float = FX
    blob_px: int = BLOB_PX
    gt_stamp_offset_ns: int = 0  # ground truth stamped this much off the depth stamp


def gt_positions(spec: BagSpec, i: int) -> np.ndarray:
    """(n_blobs, 3) ground-truth positions of frame ``i`` (metres, optical frame)."""
    k = np.arange(spec.n_blobs)
    x = -0.5 + 0.5 * k + 0.15 * np.sin(1.5 * i + k)  # fast: up to 0.22 m between frames
    y = -0.3 + 0.2 * k + 0.1 * np.cos(0.7 * i + 2 * k)
    z = 2.0 + 0.1 * k
    return np.stack([x, y, z], axis=1)


def intrinsics(spec: BagSpec) -> tuple[float, float, float, float]:
    """fx, fy, cx, cy of the test camera."""
    return spec.fx, spec.fx, (spec.width - 1) / 2.0, (spec.height - 1) / 2.0


def render_depth(spec: BagSpec, i: int) -> np.ndarray:
    """(H, W) float32 metres: background plus a square blob at each ground-truth point."""
    fx, fy, cx, cy = intrinsics(spec)
    depth = np.full((spec.height, spec.width), BACKGROUND_M, np.float32)
    for x, y, z in gt_positions(spec, i):
        u, v = int(round(fx * x / z + cx)), int(round(fy * y / z + cy))
        r = spec.blob_px
        depth[max(v - r, 0):v + r + 1, max(u - r, 0):u + r + 1] = z
    depth[0, 0] = 0.0  # one pixel without a reading
    return depth


def _header(stamp_ns: int, frame_id: str) -> Any:
    sec, nsec = divmod(stamp_ns, 1_000_000_000)
    return T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](sec=sec,
                                                                           nanosec=nsec),
                                    frame_id=frame_id)


def image_msg(stamp_ns: int, frame_id: str, pixels: np.ndarray, encoding: str) -> Any:
    """A rosbags ``sensor_msgs/msg/Image`` holding ``pixels`` as ``encoding``."""
    h, w = pixels.shape[:2]
    raw = np.ascontiguousarray(pixels)
    step = raw.nbytes // h
    return T['sensor_msgs/msg/Image'](header=_header(stamp_ns, frame_id), height=h, width=w,
                                      encoding=encoding, is_bigendian=0, step=step,
                                      data=raw.view(np.uint8).reshape(-1))


def depth_msg(spec: BagSpec, i: int, stamp_ns: int) -> Any:
    """Depth image of frame ``i`` in ``spec.depth_encoding``."""
    depth = render_depth(spec, i)
    if spec.depth_encoding == '16UC1':
        return image_msg(stamp_ns, spec.frame_id, np.round(depth * 1000).astype('<u2'),
                         '16UC1')
    if spec.depth_encoding == '32FC1':
        return image_msg(stamp_ns, spec.frame_id, depth.astype('<f4'), '32FC1')
    # Anything else: 8-bit payload with the given (unsupported) encoding name.
    return image_msg(stamp_ns, spec.frame_id, depth.astype(np.uint8), spec.depth_encoding)


def color_msg(spec: BagSpec, i: int, stamp_ns: int) -> Any:
    """Colour image of frame ``i``: blobs red on grey."""
    rgb = np.full((spec.height, spec.width, 3), 90, np.uint8)
    rgb[render_depth(spec, i) < BACKGROUND_M - 0.1] = (200, 30, 30)
    if spec.color_encoding == 'bgr8':
        return image_msg(stamp_ns, spec.frame_id, rgb[:, :, ::-1], 'bgr8')
    return image_msg(stamp_ns, spec.frame_id, rgb, spec.color_encoding)


def info_msg(spec: BagSpec, stamp_ns: int) -> Any:
    """Camera info with zero distortion."""
    fx, fy, cx, cy = intrinsics(spec)
    k = np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], np.float64)
    p = np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], np.float64)
    roi = T['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0, width=0,
                                                do_rectify=False)
    return T['sensor_msgs/msg/CameraInfo'](
        header=_header(stamp_ns, spec.frame_id), height=spec.height, width=spec.width,
        distortion_model='plumb_bob', d=np.zeros(5), k=k, r=np.eye(3).reshape(-1), p=p,
        binning_x=0, binning_y=0, roi=roi)


def cloud_msg(stamp_ns: int, frame_id: str, positions: np.ndarray) -> Any:
    """Ground-truth ``PointCloud2``: x, y, z FLOAT32 and id UINT32, unorganised."""
    dtype = np.dtype([('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('id', '<u4')])
    pts = np.zeros(len(positions), dtype)
    pts['x'], pts['y'], pts['z'] = positions.T
    pts['id'] = np.arange(len(positions))
    pf = T['sensor_msgs/msg/PointField']
    fields = [pf(name=n, offset=o, datatype=d, count=1)
              for n, o, d in (('x', 0, 7), ('y', 4, 7), ('z', 8, 7), ('id', 12, 6))]
    return T['sensor_msgs/msg/PointCloud2'](
        header=_header(stamp_ns, frame_id), height=1, width=len(pts), fields=fields,
        is_bigendian=False, point_step=16, row_step=16 * len(pts),
        data=pts.view(np.uint8).reshape(-1), is_dense=True)


def write_bag(path: Path, spec: BagSpec | None = None) -> dict[int, np.ndarray]:
    """Write a bag to ``path`` (a new directory); returns ``depth stamp -> GT positions``."""
    spec = spec or BagSpec()
    storage = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}[spec.storage]
    rows: list[tuple[int, str, str, Any]] = []  # (log time, topic, type, msg)
    truth: dict[int, np.ndarray] = {}
    for i in range(spec.frames):
        stamp = START_NS + i * PERIOD_NS
        log = stamp + spec.log_delay_ns
        if spec.info_every and i % spec.info_every == 0 and i >= spec.info_start:
            rows.append((log, spec.topics['info'], 'sensor_msgs/msg/CameraInfo',
                         info_msg(spec, stamp)))
        if i not in spec.drop_depth:
            rows.append((log + 1, spec.topics['depth'], 'sensor_msgs/msg/Image',
                         depth_msg(spec, i, stamp)))
        if i not in spec.drop_color:
            rows.append((log + 2_000_000, spec.topics['color'], 'sensor_msgs/msg/Image',
                         color_msg(spec, i, stamp + spec.color_offset_ns)))
        if spec.gt_frames is None or i in spec.gt_frames:
            truth[stamp] = gt_positions(spec, i)
            rows.append((log + 3, spec.topics['gt'], 'sensor_msgs/msg/PointCloud2',
                         cloud_msg(stamp + spec.gt_stamp_offset_ns, spec.frame_id,
                                   truth[stamp])))
    if spec.shuffle_log:
        rng = np.random.default_rng(0)
        logs = sorted(r[0] for r in rows)
        order = rng.permutation(len(rows))
        rows = [(logs[j], *rows[k][1:]) for j, k in enumerate(order)]
    writer = Writer(path, version=9, storage_plugin=storage)
    if spec.compression:
        mode = {'message': CompressionMode.MESSAGE, 'file': CompressionMode.FILE}
        writer.set_compression(mode[spec.compression], CompressionFormat.ZSTD)
    with writer:
        conns: dict[str, Any] = {}
        for _, topic, typ, _ in rows:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, typ, typestore=TS)
        for log, topic, typ, msg in sorted(rows, key=lambda r: r[0]):
            writer.write(conns[topic], log, TS.serialize_cdr(msg, typ))
    return truth


def bench_like_spec(frames: int = 6, **kw: Any) -> BagSpec:
    """640x480, Kinect-like focal length, blobs about 10 cm across."""
    return BagSpec(frames=frames, width=640, height=480, fx=525.0, blob_px=13, **kw)


def storage_file(bag: Path) -> Path:
    """The single storage file of a bag directory written by :func:`write_bag`."""
    files = [p for p in bag.iterdir() if p.name != 'metadata.yaml']
    assert len(files) == 1, files
    return files[0]


# ---------------------------------------------------------------------------------------------
# Fake estimators (real result types, blob detection instead of the paper's algorithm)
# ---------------------------------------------------------------------------------------------

def _blob_centres(frame: Any) -> np.ndarray:
    from scipy import ndimage

    depth = np.nan_to_num(frame.depth, nan=np.inf)
    mask = depth < BACKGROUND_M - 0.1
    labels, n = ndimage.label(mask)
    out = []
    intr = frame.intrinsics
    for lab in range(1, n + 1):
        v, u = np.nonzero(labels == lab)
        z = depth[v, u]
        x = (u - intr.cx) * z / intr.fx
        y = (v - intr.cy) * z / intr.fy
        out.append([x.mean(), y.mean(), z.mean()])
    return np.array(out, np.float64).reshape(-1, 3)


def fake_estimate_frame(frame: Any, params: Any = None) -> Any:
    """Single-frame fake: one candidate per depth blob (its centroid)."""
    from endeff_ros.core.single_frame import EntityEstimate, FrameEstimate
    from endeff_ros.core.types import Candidate

    centres = _blob_centres(frame)
    cands = [Candidate(position=c, node=i, geodesic=0.5, geodesic_approx=0.5,
                       path=np.stack([c, c + [0, 0.1, 0]]))
             for i, c in enumerate(centres)]
    root = centres.mean(axis=0) if len(centres) else np.zeros(3)
    entity = EntityEstimate(entity=0, root=root, candidates=cands, graph=None,
                            point_index=np.arange(len(centres)))
    n = len(centres)
    idx = np.zeros(n, np.intp)
    return FrameEstimate(points=centres, band=idx, subband=idx, entity=idx, entities=[entity],
                         unreachable=0)


class FakeTracker:
    """Temporal fake: the blob centroids, ids by x order, ``age`` counting frames seen."""

    def __init__(self, params: Any = None) -> None:
        self.params = params
        self.frames = 0

    def reset(self) -> None:
        """Forget state."""
        self.frames = 0

    def update(self, frame: Any) -> Any:
        """One frame -> TrackerResult with a track per blob (no colour: state PREDICTED)."""
        from endeff_ros.core.tracker import TrackerResult
        from endeff_ros.core.types import Track

        self.frames += 1
        est = fake_estimate_frame(frame)
        pos = est.positions()
        order = np.argsort(pos[:, 0], kind='stable')
        state = Track.DETECTED if frame.color is not None else Track.PREDICTED
        tracks = [Track(id=int(k), entity=0, position=pos[j], geodesic=0.5 + k,
                        confidence=0.9, state=state, age=self.frames,
                        path=np.stack([pos[j], pos[j] + [0, 0.1, 0]]))
                  for k, j in enumerate(order)]
        return TrackerResult(stamp_ns=frame.stamp_ns, frame_id=frame.frame_id, tracks=tracks,
                             estimate=est, stage_ms={'fake': 0.0})
