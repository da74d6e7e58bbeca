"""``main`` of a node executable: init, spin until Ctrl-C or shutdown, clean up."""

from __future__ import annotations

from typing import Any


def spin(node_factory: Any, args: list[str] | None = None) -> None:
    """Create the node with ``node_factory()`` and spin it until Ctrl-C or shutdown."""
    import rclpy
    from rclpy.executors import ExternalShutdownException

    rclpy.init(args=args)
    node = None
    try:
        node = node_factory()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
