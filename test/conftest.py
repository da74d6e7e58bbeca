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


@pytest.fixture(scope='module')
def room_bag(tmp_path_factory):
    """A quick rooms-suite bag (an empty room, procedural clips): its path and its number of
    ground-truth points (the bag tools' tests)."""
    from endeff_ros.bag.reader import BagReader
    from endeff_ros.synth.proc_clips import walk_clip, wave_clip
    from endeff_ros.synth.rooms_suite import rooms_specs
    from endeff_ros.synth.suite import write_bag

    out = tmp_path_factory.mktemp('rooms')
    clips = [walk_clip(40, name='walk_a'), wave_clip(40, name='wave_a', split='dev')]
    spec = next(s for s in rooms_specs(clips, quick=True)
                if s.pan is None and '-empty-' in s.name)
    write_bag(spec, {c.name: c for c in clips}, out)
    bag = out / 'mcap' / spec.name
    with BagReader(bag) as reader:
        points = sum(len(gt) for _, gt in reader.frames() if gt is not None)
    return bag, points
