"""Inter-process image transport benchmark: Fast DDS with and without the SHM profile.

One process publishes a 640x480 ``rgb8`` image at 30 Hz (header stamp = wall time at publish),
another subscribes and records the wall time at receipt. For each combination of profile
(on/off) and reliability (best effort/reliable) it reports the delivered fraction and the latency
percentiles as JSON::

    python -m tools.dds_bench [--seconds 5] [--rate 30] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from typing import Any

import numpy as np

from endeff_ros.cli_common import print_json
from tools.procs import ros_env, start, stop

TOPIC = '/endeff_dds_bench/image'


def _qos(reliability: str) -> Any:
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                      reliability=ReliabilityPolicy.RELIABLE if reliability == 'reliable'
                      else ReliabilityPolicy.BEST_EFFORT)


def publisher(reliability: str, frames: int, rate: float, width: int, height: int) -> int:
    """Publish ``frames`` images at ``rate`` Hz once a subscriber is matched."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import Image

    from endeff_ros.ros.convert import array_to_image_msg, make_header

    rclpy.init()
    node = rclpy.create_node('dds_bench_pub')
    pub = node.create_publisher(Image, TOPIC, _qos(reliability))
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    image = np.random.default_rng(0).integers(0, 256, (height, width, 3), dtype=np.uint8)
    msg = array_to_image_msg(make_header(0, 'bench'), image)
    deadline = time.monotonic() + 20.0
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    executor.spin_once(timeout_sec=0.5)  # let the subscriber finish matching
    t0 = time.monotonic()
    for seq in range(frames):
        target = t0 + seq / rate
        while time.monotonic() < target:
            executor.spin_once(timeout_sec=max(0.0, min(0.01, target - time.monotonic())))
        msg.header.frame_id = str(seq)
        now = time.time_ns()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
        pub.publish(msg)
    end = time.monotonic() + 1.0
    while time.monotonic() < end:  # reliable: give retransmissions a moment
        executor.spin_once(timeout_sec=0.05)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def subscriber(reliability: str, frames: int, idle: float) -> int:
    """Receive until the last frame arrives or ``idle`` s pass without any; print JSON."""
    import rclpy
    from sensor_msgs.msg import Image

    rclpy.init()
    node = rclpy.create_node('dds_bench_sub')
    latency: dict[int, float] = {}

    def on_image(msg: Image) -> None:
        now = time.time_ns()
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        latency[int(msg.header.frame_id)] = (now - stamp) / 1e6

    node.create_subscription(Image, TOPIC, on_image, _qos(reliability))
    last_count, last_change = 0, time.monotonic()
    hard = time.monotonic() + 60.0 + frames / 10.0
    while time.monotonic() < hard:
        rclpy.spin_once(node, timeout_sec=0.05)
        if len(latency) != last_count:
            last_count, last_change = len(latency), time.monotonic()
        if frames - 1 in latency or (last_count and time.monotonic() - last_change > idle):
            break
    print(json.dumps(summarise(latency, frames)), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def summarise(latency_ms: dict[int, float], sent: int) -> dict[str, Any]:
    """Delivered fraction and latency percentiles of one run."""
    values = np.array(list(latency_ms.values()), dtype=np.float64)
    out: dict[str, Any] = {'sent': sent, 'received': int(values.size),
                           'delivered': float(values.size / sent) if sent else 0.0}
    if values.size:
        p50, p95, p99 = np.percentile(values, [50, 95, 99])
        out.update(latency_ms_p50=float(p50), latency_ms_p95=float(p95),
                   latency_ms_p99=float(p99), latency_ms_max=float(values.max()))
    return out


def run_one(*, profile: bool, reliability: str, seconds: float, rate: float,
            width: int = 640, height: int = 480, domain_id: int | None = None) -> dict[str, Any]:
    """One publisher/subscriber pair in separate processes; returns the subscriber's summary."""
    frames = max(1, round(seconds * rate))
    if domain_id is None:
        domain_id = 100 + os.getpid() % 100
    env = ros_env(profile=profile, domain_id=domain_id)
    mod = ['-m', 'tools.dds_bench']
    sub = start([*mod, 'sub', '--reliability', reliability, '--frames', str(frames)], env,
                stdout=subprocess.PIPE, text=True)
    pub = start([*mod, 'pub', '--reliability', reliability, '--frames', str(frames),
                 '--rate', str(rate), '--width', str(width), '--height', str(height)], env)
    try:
        out, _ = sub.communicate(timeout=seconds + 90.0)
        result = json.loads(out.strip().splitlines()[-1])
    except (subprocess.TimeoutExpired, json.JSONDecodeError, IndexError) as exc:
        result = {'error': repr(exc)}
    finally:
        try:
            pub.wait(timeout=15.0)
        except subprocess.TimeoutExpired:
            pass
        stop(sub)
        stop(pub)
    return {'profile': profile, 'reliability': reliability, 'rate_hz': rate,
            'image': f'{width}x{height} rgb8', **result}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('role', nargs='?', default='run', choices=['run', 'pub', 'sub'])
    parser.add_argument('--reliability', default='best_effort',
                        choices=['best_effort', 'reliable'])
    parser.add_argument('--frames', type=int, default=150)
    parser.add_argument('--seconds', type=float, default=5.0)
    parser.add_argument('--rate', type=float, default=30.0)
    parser.add_argument('--width', type=int, default=640)
    parser.add_argument('--height', type=int, default=480)
    parser.add_argument('--json', help='also write the results to this file')
    args = parser.parse_args(argv)
    if args.role == 'pub':
        return publisher(args.reliability, args.frames, args.rate, args.width, args.height)
    if args.role == 'sub':
        return subscriber(args.reliability, args.frames, idle=3.0)
    results = [run_one(profile=profile, reliability=rel, seconds=args.seconds, rate=args.rate,
                       width=args.width, height=args.height)
               for profile in (True, False) for rel in ('best_effort', 'reliable')]
    print_json({'dds_image_transport': results}, args.json)
    return 0


if __name__ == '__main__':
    sys.exit(main())
