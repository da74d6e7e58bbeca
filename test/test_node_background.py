"""The node's ``~/reset_background`` service (std_srvs/Trigger), in-process over DDS."""

from __future__ import annotations

import pytest
import rclpy
from ros_helpers import spin_until

from endeff_ros.core.params import EndeffParams

pytestmark = pytest.mark.integration


class BackgroundTracker:
    """Counts the re-learns asked for; never gets a frame here."""

    def __init__(self, params: EndeffParams) -> None:
        self.params = params
        self.relearns = 0

    def reset_background(self) -> None:
        self.relearns += 1


class PlainTracker:
    """A tracker without a static background."""

    def __init__(self, params: EndeffParams) -> None:
        self.params = params


def _call(factory, namespace: str):
    from rclpy.executors import SingleThreadedExecutor
    from std_srvs.srv import Trigger

    from endeff_ros.ros.node import EndeffNode

    node = EndeffNode(tracker_factory=factory, namespace=namespace)
    tester = rclpy.create_node('tester', namespace=namespace)
    client = tester.create_client(Trigger, 'endeff_node/reset_background')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    executor.add_node(tester)
    try:
        assert spin_until(executor, client.service_is_ready), 'no reset_background service'
        future = client.call_async(Trigger.Request())
        assert spin_until(executor, future.done)
        return node.tracker, future.result()
    finally:
        executor.shutdown()
        node.destroy_node()
        tester.destroy_node()


def test_reset_background_service_relearns(ros_context):
    tracker, response = _call(BackgroundTracker, '/bg')
    assert response.success and 're-learnt' in response.message
    assert tracker.relearns == 1


def test_reset_background_service_without_a_background(ros_context):
    tracker, response = _call(PlainTracker, '/plain')
    assert not response.success and 'no static background' in response.message
