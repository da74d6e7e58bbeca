"""tools.seen_ceiling: the recall an estimator could reach from what the depth sees."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tools import seen_ceiling


def test_a_bag_the_depth_sees_whole_has_every_ceiling_at_its_seen_share(room_bag):
    bag, points = room_bag
    r = seen_ceiling.check_bag(bag)
    assert r['points'] == points
    assert r['seen'] > 0.9 * points  # one person in an empty room, in view
    c = r['ceiling']
    assert 0.9 < c['hold_0'] <= c['hold_8'] <= c['hold_30'] <= c['ever'] <= 1.0


def test_hidden_points_count_only_within_the_hold(room_bag, monkeypatch):
    """The depth sees every point in the first frame and none after it: a hold of k frames
    keeps the k frames after the first, and every frame keeps the points seen once."""
    bag, _ = room_bag
    calls = {'n': 0}

    def first_frame_only(labels, depth, intrinsics, **kwargs):
        calls['n'] += 1
        return np.full(len(labels), calls['n'] == 1)

    monkeypatch.setattr(seen_ceiling, 'seen_labels', first_frame_only)
    r = seen_ceiling.check_bag(bag)
    frames = calls['n']
    assert frames > 9
    c = r['ceiling']
    # Per-frame recall: 1 in the first frame and the k after it, 0 after; mean over frames.
    assert c['hold_0'] == pytest.approx(1 / frames)
    assert c['hold_8'] == pytest.approx(9 / frames)
    assert c['hold_30'] == pytest.approx(min(31, frames) / frames)
    assert c['ever'] == pytest.approx(1.0)
    assert 0 < r['seen'] <= 5  # the first frame's points: one person's five at most


def test_never_seen_points_are_out_of_reach(room_bag, monkeypatch):
    bag, points = room_bag
    monkeypatch.setattr(seen_ceiling, 'seen_labels',
                        lambda labels, *a, **k: np.zeros(len(labels), bool))
    r = seen_ceiling.check_bag(bag)
    assert r['seen'] == 0 and r['points'] == points
    assert set(r['ceiling'].values()) == {0.0}


def test_report_gives_the_overall_and_the_groups(room_bag, tmp_path):
    bag, _ = room_bag
    out = tmp_path / 'c.json'
    assert seen_ceiling.main([str(bag), '--json', str(out)]) == 0
    report = json.loads(out.read_text())
    assert report['overall']['bags'] == 1
    assert report['overall']['hold_0'] == pytest.approx(report['bags'][0]['ceiling']['hold_0'],
                                                        abs=1e-3)
    assert 'room=empty' in report['groups']
    assert report['groups']['room=empty']['points'] == report['overall']['points']
