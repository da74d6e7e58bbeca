"""Motion-capture clips for the ``mocap`` suite: readers, retargeting and the clip catalogue."""

from __future__ import annotations

from .clip import FAMILIES, JOINT_INDEX, JOINTS, SPLITS, MotionClip

__all__ = ['FAMILIES', 'JOINTS', 'JOINT_INDEX', 'SPLITS', 'MotionClip']
