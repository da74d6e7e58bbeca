"""A trivial relay node, the latency baseline of ``latency_bench``.

Subscribes to ``depth/image_raw`` with the same QoS as ``endeff_node`` and publishes, for every
depth image, an empty ``relay/end_effectors`` cloud stamped with the depth header (built by the
same :func:`endeff_ros.ros.convert.tracks_to_cloud`). The difference between its latency and the
node's is what synchronisation, conversion and the tracker cost.

    python -m tools.relay --ros-args -r __ns:=/camera
"""

from __future__ import annotations

from typing import Any

from rclpy.node import Node
from sensor_msgs.msg import Image, PointCloud2

from endeff_ros.ros import convert
from endeff_ros.ros.executable import spin
from endeff_ros.ros.ros_params import qos


class RelayNode(Node):
    """depth/image_raw in, relay/end_effectors (empty cloud, same stamp) out."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('endeff_relay', **kwargs)
        reliability = self.declare_parameter('input_reliability', 'best_effort').value
        self.pub = self.create_publisher(PointCloud2, 'relay/end_effectors', qos('reliable', 5))
        self.sub = self.create_subscription(Image, 'depth/image_raw', self._on_depth,
                                            qos(reliability, 5))

    def _on_depth(self, msg: Image) -> None:
        convert.depth_image_to_array(msg)  # decode, as the node does
        self.pub.publish(convert.tracks_to_cloud(msg.header, []))


def main(args: list[str] | None = None) -> None:
    """Entry point: spin the relay until interrupted."""
    spin(RelayNode, args)


if __name__ == '__main__':
    main()
