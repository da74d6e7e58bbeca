"""tools.track_history: every missed ground-truth point by its history, and the lost track."""

from __future__ import annotations

import dataclasses
import json

from endeff_ros.core.params import EndeffParams
from tools import track_history


def test_every_point_gets_one_history(room_bag):
    bag, points = room_bag
    r = track_history.check_bag(bag)
    assert set(r['history']) == {'head', 'hand', 'foot'}
    assert sum(sum(h.values()) for h in r['history'].values()) == points
    assert sum(h['found'] for h in r['history'].values()) > 0
    # Every recent miss has its lost track's fate, and only those.
    for kind, h in r['history'].items():
        fates = r['lost_track'].get(kind, dict.fromkeys(track_history.LOST, 0))
        assert sum(fates.values()) == h['within_10'] + h['within_30']


def test_drop_reasons_follow_the_tracker_rules(room_bag):
    """With confirmation out of reach every dropped track is unconfirmed or left the
    foreground (case C never keeps one, so none expires or outlives its detections)."""
    bag, _ = room_bag
    params = dataclasses.replace(EndeffParams(), confirm_hits=1000)
    r = track_history.check_bag(bag, params)
    fates = {n: sum(f[n] for f in r['lost_track'].values()) for n in track_history.LOST}
    assert fates['gone_expired'] == fates['gone_short'] == 0
    assert fates['gone_unconfirmed'] > 0


def test_main_writes_the_totals(room_bag, tmp_path, capsys):
    bag, points = room_bag
    out = tmp_path / 'history.json'
    assert track_history.main([str(bag.parent), '--json', str(out)]) == 0
    report = json.loads(out.read_text())
    assert sum(sum(h.values()) for h in report['history'].values()) == points
    assert [b['bag'] for b in report['bags']] == [bag.name]
