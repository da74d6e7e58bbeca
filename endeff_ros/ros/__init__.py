"""ROS 2 adapter of endeff_ros: message conversion and the node.

- ``convert``        message <-> numpy (imports rclpy lazily, only in the output builders)
- ``node``           the ``endeff_node`` executable (thin wiring around ``endeff_ros.core``)
- ``scheduler``      the node's scheduling without ROS: synchronisation, early work, resets
- ``processing``     node-independent pieces of the node: parameter table, slots, statistics
- ``executable``     init / spin / shutdown of a node executable
"""
