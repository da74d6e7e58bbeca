"""tools.id_switches: each id switch of the temporal estimator by its cause, and when it came."""

from __future__ import annotations

import json

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
