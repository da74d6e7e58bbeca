"""ROS 2 adapter of endeff_ros: message conversion, the node, DDS tools.

- ``convert``        message <-> numpy (imports rclpy lazily, only in the output builders)
- ``node``           the ``endeff_node`` executable (thin wiring around ``endeff_ros.core``)
- ``processing``     node-independent pieces of the node: latest-set slot, statistics
- ``latency_bench``  end-to-end latency of the node against a trivial relay
"""
