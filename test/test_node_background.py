"""The node's ``~/reset_background`` and ``~/learn_empty_background`` services
(std_srvs/Trigger), in-process over DDS."""

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
        self.empty: list[bool] = []

    def reset_background(self, *, empty: bool = False) -> None:
        self.relearns += 1
        self.empty.append(empty)


class PlainTracker:
    """A tracker without a static background."""

    def __init__(self, params: EndeffParams) -> None:
        self.params = params


def _call(factory, namespace: str, service: str = 'reset_background'):
    from rclpy.executors import SingleThreadedExecutor
    from std_srvs.srv import Trigger

    from endeff_ros.ros.node import EndeffNode

    node = EndeffNode(tracker_factory=factory, namespace=namespace)
    tester = rclpy.create_node('tester', namespace=namespace)
    client = tester.create_client(Trigger, f'endeff_node/{service}')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    executor.add_node(tester)
    try:
        assert spin_until(executor, client.service_is_ready), f'no {service} service'
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
    assert tracker.relearns == 1 and tracker.empty == [False]


def test_learn_empty_background_service_learns_all_in_view(ros_context):
    tracker, response = _call(BackgroundTracker, '/bg_empty', 'learn_empty_background')
    assert response.success and 'empty room' in response.message
    assert tracker.empty == [True]


def test_reset_background_service_without_a_background(ros_context):
    tracker, response = _call(PlainTracker, '/plain')
    assert not response.success and 'no static background' in response.message
