"""Fixtures shared by the test modules (pytest finds them here; no imports needed)."""

from __future__ import annotations

import os

import pytest


@pytest.fixture(scope='session')
def ros_context():
    """rclpy initialised once per session, on a private DDS domain, so that other test runs on
    this machine (and their /diagnostics) stay apart."""
    import rclpy

    rclpy.init(domain_id=200 + os.getpid() % 30)
    yield
    rclpy.shutdown()
