"""Ids that hold: an end-effector lost for longer than the tracker keeps a track alive on its
prediction (T frames) takes its id back when found again where it was, or farther on when its
geodesic distance to the root, its kind and its direction from the root say it is the same
limb; never another end's id, and no id is given twice."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scenarios as sc

from endeff_ros.core.params import EndeffParams
from endeff_ros.core.tracker import Tracker, _Lost
from endeff_ros.core.types import Track

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


def _moving_star_limb_away(n_gone: int, step: float) -> list[sc.Shot]:
    """A star rising ``step`` m a frame whose limb 0 is gone for ``n_gone`` frames (from frame
    6 on) and then comes back, found again ``(n_gone + 1) * step`` m above where it was lost.
    Labels: 'all', 'gone', 'back'."""
    plan = [('all', None)] * 6 + [('gone', (1, 2, 3, 4))] * n_gone + [('back', None)] * 2
    return [sc.shoot(sc.scenes.star(5, keep=keep, length=sc.STAR_LENGTH, height=1.0 + i * step),
                     i, label=label) for i, (label, keep) in enumerate(plan)]


def _tip(shot: sc.Shot, limb: int) -> np.ndarray:
    return shot.gt[limb]


@pytest.mark.parametrize(('far', 'same'), [(0.8, True), (0.0, False)])
def test_a_limb_lost_while_its_entity_moves_takes_its_id_back_from_farther(far, same):
    """The star moves on while a limb is gone and the limb comes back 0.45 m from where its
    track was lost, beyond ``revive_distance``: with the same geodesic distance to the root
    it is the same limb and takes its id back (``revive_far_distance``); without that
    second radius it gets a new id. The other limbs keep theirs throughout and the id comes
    back to no other end."""
    shots = _moving_star_limb_away(8, 0.05)
    tracker = Tracker(EndeffParams(background=False, revive_far_distance=far))
    results = [tracker.update(s.frame).tracks for s in shots]
    last_seen = 5
    before = _nearest_id(results[last_seen], _tip(shots[last_seen], 0))
    gone = [i for i, s in enumerate(shots) if s.label == 'gone']
    assert all(before not in {t.id for t in results[i]} for i in gone[1:])
    back = len(shots) - 2  # the first frame with the limb back
    moved = np.linalg.norm(_tip(shots[back], 0) - _tip(shots[last_seen], 0))
    assert 0.3 < moved < 0.8
    after = _nearest_id(results[back], _tip(shots[back], 0))
    assert (after == before) is same
    assert after == _nearest_id(results[-1], _tip(shots[-1], 0))
    others = [_nearest_id(results[last_seen], _tip(shots[last_seen], k)) for k in range(1, 5)]
    assert others == [_nearest_id(results[back], _tip(shots[back], k)) for k in range(1, 5)]
    assert after not in others


def _lost_and_found(lost: list[tuple[float, float]], found: list[tuple[float, float]],
                    **params: float) -> tuple[list[int], list[int]]:
    """Ids given to new ends ``found`` (x position on a line, geodesic distance to the root)
    by a tracker that has just lost tracks ``lost`` (ids 100, 101, ...) at such positions."""
    tracker = Tracker(EndeffParams(**params))
    tracker._frame = 1
    ids = [100 + k for k in range(len(lost))]
    tracker._lost = [_Lost(i, np.array([x, 0.0, 2.0]), 1, np.array([x, 0.0, 2.0]), g)
                     for i, (x, g) in zip(ids, lost)]
    tracker._next_id = 200
    got = tracker._revived_ids([np.array([x, 0.0, 2.0]) for x, _ in found],
                               [g for _, g in found])
    return ids, got


def test_beyond_revive_distance_only_the_same_limb_takes_an_id_back():
    """0.5 m from where a hand (geodesic distance 0.8 m) was lost: an end 0.8 m from the
    root takes its id, an end 0.3 m from the root (a head, a knee) does not; within
    ``revive_distance`` the position alone decides."""
    (hand,), got = _lost_and_found([(0.0, 0.8)], [(0.5, 0.85)])
    assert got == [hand]
    _, got = _lost_and_found([(0.0, 0.8)], [(0.5, 0.3)])
    assert got == [200]
    _, got = _lost_and_found([(0.0, 0.8)], [(0.9, 0.8)])
    assert got == [200]  # beyond revive_far_distance
    _, got = _lost_and_found([(0.0, 0.8)], [(0.2, 0.3)])
    assert got == [hand]


def test_two_lost_hands_found_again_are_not_merged():
    """Two hands lost 0.6 m apart with the same geodesic distance, found again each 0.4 m on
    towards the other's old place (they crossed): each new end takes one id, the nearer
    pair first, and no id is given twice."""
    (a, b), got = _lost_and_found([(0.0, 0.8), (0.6, 0.8)], [(0.4, 0.8), (0.15, 0.8)])
    assert sorted(got) == [a, b]
    assert got == [b, a]  # 0.4 is 0.2 from b; 0.15 is 0.15 from a
    (a, b), got = _lost_and_found([(0.0, 0.8), (0.6, 0.8)], [(0.45, 0.8), (0.5, 0.8)])
    assert len(set(got)) == 2 and b in got  # one takes b (0.1 m), the other a (0.45 m)


def _revived(lost: _Lost, found: np.ndarray, geodesic: float, kind: int,
             root: np.ndarray) -> int:
    """The id a tracker that has just lost ``lost`` (id 100) gives a new end at ``found``
    with this geodesic distance and frame kind, in an entity whose root is at ``root``."""
    tracker = Tracker(EndeffParams())
    tracker._frame = 1
    tracker._lost = [lost]
    tracker._next_id = 200
    return tracker._revived_ids([found], [geodesic], [kind], [found - root])[0]


def test_a_lost_hand_is_not_revived_onto_a_foot():
    """A hand (geodesic distance 0.75 m) lost beside the hip, 0.35 m out to the side of the
    root (camera frame, y down): a foot found 0.78 m away with a geodesic distance within
    ``revive_geodesic_tolerance`` (0.9 m) leaves the root downwards, and gets a new id; the
    hand found 0.47 m on, raised out to the same side, takes its id back. A lost head gives
    its id to no end beyond ``revive_distance``, and no end this frame calls a head takes
    a lost hand's id from there."""
    root = np.array([0.0, 0.0, 2.5])
    seen = root + [0.35, 0.1, 0.0]
    hand = _Lost(100, seen, 1, seen, 0.75, Track.KIND_HAND, seen - root)
    foot = root + [0.15, 0.85, 0.0]
    assert 0.3 < np.linalg.norm(foot - seen) < 0.8
    assert _revived(hand, foot, 0.9, Track.KIND_FOOT, root) == 200
    raised = root + [0.6, -0.3, 0.0]
    assert 0.3 < np.linalg.norm(raised - seen) < 0.8
    assert _revived(hand, raised, 0.8, Track.KIND_HAND, root) == 100
    assert _revived(hand, raised, 0.8, Track.KIND_HEAD, root) == 200
    head = _Lost(100, seen, 1, seen, 0.75, Track.KIND_HEAD, seen - root)
    assert _revived(head, raised, 0.8, Track.KIND_HAND, root) == 200
    assert _revived(head, seen + [0.1, -0.1, 0.0], 0.8, Track.KIND_HAND, root) == 100
