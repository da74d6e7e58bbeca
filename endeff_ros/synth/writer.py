"""Write synthetic frames as rosbag2 bags in the form of ``docs/benchmark-bags.md``.

Uses rosbags' ``Writer`` and the ROS 2 Jazzy typestore (no rclpy). One call writes the same
frames to one or more storages (``sqlite3``, ``mcap``). Log (receive) times are the header
stamps plus a small random delay.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
import numpy.typing as npt
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from ..bag.outputs import partial_dir, remove, replace_into_place, sweep_stale_partials
from ..core.types import Intrinsics
from .frames import SynthFrame
from .sensor import depth_to_mm
from .sequences import SequenceSpec

COLOR_TOPIC = '/camera/color/image_raw'
DEPTH_TOPIC = '/camera/depth/image_raw'
INFO_TOPIC = '/camera/depth/camera_info'
GT_TOPIC = '/ground_truth/end_effectors'
STORAGES = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}

_TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def typestore():
    """The ROS 2 Jazzy rosbags typestore used for every message."""
    return _TYPESTORE


class _Msgs:
    """Builders of the four message types."""

    def __init__(self) -> None:
        ts = _TYPESTORE
        self.Time = ts.types['builtin_interfaces/msg/Time']
        self.Header = ts.types['std_msgs/msg/Header']
        self.Image = ts.types['sensor_msgs/msg/Image']
        self.CameraInfo = ts.types['sensor_msgs/msg/CameraInfo']
        self.Roi = ts.types['sensor_msgs/msg/RegionOfInterest']
        self.PointCloud2 = ts.types['sensor_msgs/msg/PointCloud2']
        self.PointField = ts.types['sensor_msgs/msg/PointField']

    def header(self, stamp_ns: int, frame_id: str):
        return self.Header(stamp=self.Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
                           frame_id=frame_id)

    def image(self, stamp_ns: int, frame_id: str, data: np.ndarray, encoding: str):
        h, w = data.shape[:2]
        raw = np.ascontiguousarray(data).view(np.uint8).reshape(-1)
        return self.Image(header=self.header(stamp_ns, frame_id), height=h, width=w,
                          encoding=encoding, is_bigendian=0, step=raw.size // h, data=raw)

    def info(self, stamp_ns: int, frame_id: str, intr: Intrinsics):
        k = intr.k_matrix().reshape(-1)
        p = np.array([intr.fx, 0, intr.cx, 0, 0, intr.fy, intr.cy, 0, 0, 0, 1, 0], float)
        return self.CameraInfo(
            header=self.header(stamp_ns, frame_id), height=intr.height, width=intr.width,
            distortion_model='plumb_bob', d=np.zeros(5), k=k, r=np.eye(3).reshape(-1), p=p,
            binning_x=0, binning_y=0,
            roi=self.Roi(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))

    def cloud(self, stamp_ns: int, frame_id: str, pts: npt.NDArray[np.float64],
              ids: npt.NDArray[np.uint32]):
        rec = np.zeros(len(pts), dtype=[('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('id', '<u4')])
        rec['x'], rec['y'], rec['z'] = pts[:, 0], pts[:, 1], pts[:, 2]
        rec['id'] = ids
        pf = self.PointField
        fields = [pf(name='x', offset=0, datatype=pf.FLOAT32, count=1),
                  pf(name='y', offset=4, datatype=pf.FLOAT32, count=1),
                  pf(name='z', offset=8, datatype=pf.FLOAT32, count=1),
                  pf(name='id', offset=12, datatype=pf.UINT32, count=1)]
        return self.PointCloud2(header=self.header(stamp_ns, frame_id), height=1,
                                width=len(pts), fields=fields, is_bigendian=False,
                                point_step=16, row_step=16 * len(pts),
                                data=rec.view(np.uint8).reshape(-1), is_dense=True)


def frame_messages(frame: SynthFrame, spec: SequenceSpec, rng: np.random.Generator,
                   msgs: _Msgs | None = None) -> list[tuple[int, str, str, bytes]]:
    """(log time ns, topic, type, CDR bytes) of one frame, sorted by log time."""
    m = msgs or _Msgs()
    ts = _TYPESTORE
    out = []
    delay = rng.integers(1_000_000, 6_000_000, size=2)
    fid = frame.frame_id
    if frame.depth is not None:
        log = frame.stamp_ns + int(delay[0])
        if spec.depth_encoding == '16UC1':
            img = m.image(frame.stamp_ns, fid, depth_to_mm(frame.depth), '16UC1')
        else:
            img = m.image(frame.stamp_ns, fid, frame.depth.astype('<f4'), '32FC1')
        out.append((log, DEPTH_TOPIC, img.__msgtype__, img))
        if frame.index % spec.info_every == 0:
            info = m.info(frame.stamp_ns, fid, frame.intrinsics)
            out.append((log + 100_000, INFO_TOPIC, info.__msgtype__, info))
        cloud = m.cloud(frame.stamp_ns, fid, frame.gt, frame.gt_ids)
        out.append((log + 200_000, GT_TOPIC, cloud.__msgtype__, cloud))
    if frame.color is not None:
        col = frame.color if spec.color_encoding == 'rgb8' else frame.color[..., ::-1]
        img = m.image(frame.color_stamp_ns, fid, col, spec.color_encoding)
        out.append((frame.color_stamp_ns + int(delay[1]), COLOR_TOPIC, img.__msgtype__, img))
    out.sort(key=lambda x: x[0])
    return [(t, topic, typ, bytes(ts.serialize_cdr(msg, typ))) for t, topic, typ, msg in out]


def write_bags(frames: Iterable[SynthFrame], spec: SequenceSpec, paths: dict[str, Path],
               seed: int = 0,
               custom_data: Callable[[], dict[str, str]] | None = None,
               compress: bool = False) -> int:
    """Write ``frames`` to one bag per storage (``paths``: storage name -> bag directory).

    ``custom_data`` is called once all frames are written (so it may describe them) and its
    string pairs go into the rosbag2 metadata's ``custom_data``. ``compress`` zstd-compresses
    the chunks of ``mcap`` bags (rosbag2's storage compression, read transparently by rosbags
    and ros2 bag; depth shrinks about 5x, noisy colour 1.2x). Returns the number of frames
    written.

    Each bag is written in a hidden sibling directory (:func:`~endeff_ros.bag.outputs.partial_dir`)
    and moved to its path, replacing a bag there, only once complete: rosbags closes a writer
    left by an exception as a complete-looking bag with fewer frames, and a worker killed
    before it could remove one (SIGKILL, the end of its grace period) would leave it under the
    bag's own name. An interrupted write removes its directories; one left by a killed process
    is hidden from bag searches and swept by the next write of that bag.
    """
    final = {storage: Path(path) for storage, path in paths.items()}
    aside: dict[str, Path] = {}
    writers = []
    try:
        for storage, path in final.items():
            path.parent.mkdir(parents=True, exist_ok=True)
            sweep_stale_partials(path)
            aside[storage] = partial_dir(path)
            remove(aside[storage])
            aside[storage].mkdir()
            # Inside it under the bag's own name: rosbags names the storage file after it.
            w = Writer(aside[storage] / path.name, version=9, storage_plugin=STORAGES[storage])
            if compress and storage == 'mcap':
                w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            w.open()
            writers.append(w)
        count = _write_frames(writers, frames, spec, seed, custom_data)
        for storage, path in final.items():
            replace_into_place(aside[storage] / path.name, path, aside[storage])
            remove(aside[storage])  # with the bag it replaced
    except BaseException:
        for path in aside.values():
            remove(path)
        raise
    return count


def _write_frames(writers: list[Writer], frames: Iterable[SynthFrame], spec: SequenceSpec,
                  seed: int, custom_data: Callable[[], dict[str, str]] | None) -> int:
    """Write ``frames`` through the open ``writers`` and close them; returns the count."""
    try:
        conns = [{} for _ in writers]
        topics = ((DEPTH_TOPIC, 'sensor_msgs/msg/Image'), (COLOR_TOPIC, 'sensor_msgs/msg/Image'),
                  (INFO_TOPIC, 'sensor_msgs/msg/CameraInfo'),
                  (GT_TOPIC, 'sensor_msgs/msg/PointCloud2'))
        for w, c in zip(writers, conns):
            for topic, typ in topics:
                c[topic] = w.add_connection(topic, typ, typestore=_TYPESTORE)
        rng = np.random.default_rng([seed, 5, sum(map(ord, spec.name))])
        msgs = _Msgs()
        count = 0
        for frame in frames:
            for log, topic, _, data in frame_messages(frame, spec, rng, msgs):
                for w, c in zip(writers, conns):
                    w.write(c[topic], log, data)
            count += 1
        if custom_data is not None:
            for key, value in custom_data().items():
                for w in writers:
                    w.set_custom_data(key, value)
    finally:
        for w in writers:
            w.close()
    return count
