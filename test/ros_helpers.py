"""Helpers shared by the ROS tests: message builders and bounded spinning (no bare sleeps)."""

from __future__ import annotations

import array
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from endeff_ros.ros import convert


def image_msg(array_: np.ndarray, encoding: str, stamp_ns: int, frame_id: str) -> Any:
    """An rclpy Image of a (H, W[, C]) array (little-endian, no padding)."""
    from sensor_msgs.msg import Image

    msg = Image()
    msg.header = convert.make_header(stamp_ns, frame_id)
    msg.height, msg.width = array_.shape[:2]
    msg.encoding = encoding
    msg.is_bigendian = False
    msg.step = int(array_.strides[0])
    msg.data = array.array('B', np.ascontiguousarray(array_).tobytes())
    return msg


def info_msg(stamp_ns: int, frame_id: str, w: int, h: int, f: float = 500.0) -> Any:
    """An rclpy CameraInfo with a pinhole K (f = 0 gives an uncalibrated, zero K)."""
    from sensor_msgs.msg import CameraInfo

    msg = CameraInfo()
    msg.header = convert.make_header(stamp_ns, frame_id)
    msg.width, msg.height = w, h
    msg.k = [f, 0.0, w / 2.0, 0.0, f, h / 2.0, 0.0, 0.0, 1.0 if f else 0.0]
    return msg


def spin_until(executor: Any, condition: Callable[[], bool], timeout: float = 10.0) -> bool:
    """Spin ``executor`` in bounded steps until ``condition()`` or the deadline."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        executor.spin_once(timeout_sec=0.05)
    return condition()
