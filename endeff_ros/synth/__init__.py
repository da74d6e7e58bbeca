"""Synthetic RGB-D benchmark sequences with ground-truth end-effectors.

``render_sequence(name)`` yields ``SynthFrame`` objects (depth, colour, intrinsics, ground truth)
without touching any bag; ``endeff synth`` writes them as rosbag2 bags in the form of
``docs/benchmark-bags.md`` and ``endeff sheet`` draws a contact sheet of such bags.
This package never imports rclpy.
"""

from __future__ import annotations

from .frames import SynthFrame, render_person_frame, render_sequence
from .sequences import GROUPS, SEQUENCES

__all__ = ['GROUPS', 'SEQUENCES', 'SynthFrame', 'render_person_frame', 'render_sequence']
