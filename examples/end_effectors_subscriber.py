"""Print the hands (or any kind) that endeff_node publishes: a minimal subscriber.

Run it beside the node:  python3 end_effectors_subscriber.py [--kind hand] [--count N]
(topic /camera/end_effectors; remap with --ros-args -r end_effectors:=/other/end_effectors).
"""

import argparse

import numpy as np
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2, PointField

KINDS = {0: 'other', 1: 'head', 2: 'hand', 3: 'foot'}
STATES = {0: 'detected', 1: 'predicted'}
NUMPY = {PointField.UINT8: 'u1', PointField.UINT32: 'u4', PointField.FLOAT32: 'f4'}


def read_points(msg):
    """The cloud as a numpy structured array, fields read by name and offset."""
    order = '>' if msg.is_bigendian else '<'
    dtype = np.dtype({'names': [f.name for f in msg.fields],
                      'formats': [order + NUMPY[f.datatype] for f in msg.fields],
                      'offsets': [f.offset for f in msg.fields],
                      'itemsize': msg.point_step})
    return np.frombuffer(bytes(msg.data), dtype=dtype, count=msg.width * msg.height)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--kind', default='hand', choices=[*KINDS.values(), 'any'])
    parser.add_argument('--count', type=int, default=0, help='exit after N clouds (0: never)')
    args, ros_args = parser.parse_known_args()
    rclpy.init(args=ros_args)
    node = rclpy.create_node('hand_printer')
    received = []

    def on_cloud(msg):
        received.append(msg.header.stamp)
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        for p in read_points(msg):
            kind = KINDS.get(int(p['kind']), 'other')
            if args.kind not in ('any', kind):
                continue
            print(f'{t:.3f} {msg.header.frame_id}: {kind} {p["id"]} of entity {p["entity"]} '
                  f'at ({p["x"]:.2f}, {p["y"]:.2f}, {p["z"]:.2f}) m, '
                  f'{STATES.get(int(p["state"]), "?")}, confidence {p["confidence"]:.2f}, '
                  f'velocity ({p["vx"]:.2f}, {p["vy"]:.2f}, {p["vz"]:.2f}) m/s', flush=True)

    # Reliable, keep last 5: what the node offers (a best-effort subscriber matches too).
    qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(PointCloud2, '/camera/end_effectors', on_cloud, qos)
    try:
        while rclpy.ok() and (args.count <= 0 or len(received) < args.count):
            rclpy.spin_once(node, timeout_sec=0.1)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
