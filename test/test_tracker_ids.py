"""Ids that hold: an end-effector lost for longer than the tracker keeps a track alive on its
prediction (T frames) takes its id back when found again where it was."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scenarios as sc

from endeff_ros.core.params import EndeffParams
from endeff_ros.core.tracker import Tracker

TOL = 0.15


@functools.cache
def _limb_away(n_gone: int) -> list[sc.Shot]:
    """A star whose limb 0 is gone for ``n_gone`` frames and then comes back."""
    whole = sc.star_limb_vanishes(6, n_gone)
    back = [sc.shoot(sc.scenes.star(5, length=sc.STAR_LENGTH), len(whole) + i, label='back')
            for i in range(4)]
    return whole + back


def _nearest_id(tracks, point):
    d = [np.linalg.norm(t.position - point) for t in tracks]
    k = int(np.argmin(d))
    assert d[k] < TOL
    return tracks[k].id


@pytest.mark.parametrize(('revive_frames', 'same'), [(30, True), (10, False)])
def test_a_limb_gone_for_longer_than_t_takes_its_id_back_within_revive_frames(
        revive_frames, same):
    shots = _limb_away(20)  # gone 20 frames, more than T = 8
    tracker = Tracker(EndeffParams(background=False, keep_frames=8,
                                   revive_frames=revive_frames))
    results = [tracker.update(s.frame).tracks for s in shots]
    tip = sc.star_tip(5, 0)
    before = _nearest_id(results[5], tip)
    assert all(before not in {t.id for t in results[i]} for i in range(6 + 8, 26))
    after = _nearest_id(results[-1], tip)
    assert (after == before) is same
    others = {_nearest_id(results[5], sc.star_tip(5, k)) for k in range(1, 5)}
    assert after not in others  # never another end's id
