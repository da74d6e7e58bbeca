"""tools.id_switches: each id switch of the temporal estimator by its cause, and when it came."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np

from tools import id_switches


def test_windows_count_every_switch_and_every_label(room_bag, tmp_path):
    bag, n_points = room_bag
    # Ids never given back: a walk and a wave then switch whenever a track is lost.
    out = id_switches.check_bag(bag, id_switches.EndeffParams(revive_distance=0.0,
                                                              revive_far_distance=0.0))
    by_cause = sum(sum(c.values()) for c in out['switches'].values())
    assert by_cause > 0
    assert sum(w['switches'] for w in out['windows'].values()) == by_cause
    assert sum(w['labels'] for w in out['windows'].values()) == n_points
    duplicates = sum(c['duplicate_new'] + c['duplicate_old'] for c in out['switches'].values())
    assert sum(v for k, v in out['detail'].items() if ':old_' in k) == duplicates
    report = tmp_path / 'switches.json'
    assert id_switches.main([str(bag), '--json', str(report)]) == 0
    figures = json.loads(report.read_text())
    assert list(figures['windows']) == ['frames_0-9', 'frames_10-29', 'frames_30+']
    first = figures['windows']['frames_0-9']
    assert first['end_effector_minutes'] > 0
    assert abs(first['per_minute'] - first['switches'] / first['end_effector_minutes']) < 0.01


def test_window_names_cover_every_frame():
    assert id_switches._window(0) == 'frames_0-9'
    assert id_switches._window(29) == 'frames_10-29'
    assert id_switches._window(10**6) == 'frames_30+'


def _track(track_id, x, *, detected=True, entity=0):
    return SimpleNamespace(id=track_id, entity=entity, position=np.array([x, 0.0, 2.0]),
                           detected=detected)


def test_births_beside_a_prediction_are_tallied_with_who_keeps_the_truth():
    tally = id_switches.BirthTally()
    tally.births(0, [_track(1, 0.0), _track(5, 1.0)])
    tally.matched(0, {7: 1, 9: 5})
    # Track 1 goes on predicted; 2 is born 0.15 m from it and takes its truth (key 7); 3,
    # born 0.4 m from 5 (predicted), does not take 5's truth, which 5 keeps. 4, in another
    # entity, is no birth beside a prediction of its own.
    tally.births(1, [_track(1, 0.0, detected=False), _track(2, 0.15),
                     _track(5, 1.0, detected=False), _track(3, 1.4),
                     _track(4, 0.05, entity=1)])
    tally.matched(1, {7: 2, 9: 5})
    assert tally.counts == {'0.1-0.2 m': {'A': 0, 'B': 1, 'none': 0},
                            '0.3-0.5 m': {'A': 1, 'B': 0, 'none': 0}}
    # A birth whose truth nobody holds for BIRTH_OUTCOME_FRAMES frames is 'none'; so is
    # one still waiting when the bag ends.
    tally.births(2, [_track(2, 0.15, detected=False), _track(6, 0.4)])
    last = 2 + id_switches.BIRTH_OUTCOME_FRAMES - 1
    for index in range(2, last):
        tally.matched(index, {})
    assert '0.2-0.3 m' not in tally.counts  # still waiting
    tally.matched(last, {11: 6})  # 6 matches another truth: the birth's outcome is 'none'
    tally.births(last + 1, [_track(6, 0.4, detected=False), _track(8, 0.45)])
    counts = tally.close()
    assert counts['0.2-0.3 m'] == {'A': 0, 'B': 0, 'none': 1}
    assert counts['0-0.1 m'] == {'A': 0, 'B': 0, 'none': 1}
