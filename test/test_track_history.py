"""tools.track_history: every missed ground-truth point by its history, and the lost track."""

from __future__ import annotations

import dataclasses
import json

import pytest

from endeff_ros.bag.reader import BagReader
from endeff_ros.core.params import EndeffParams
from endeff_ros.synth.proc_clips import walk_clip, wave_clip
from endeff_ros.synth.rooms_suite import rooms_specs
from endeff_ros.synth.suite import write_bag
from tools import track_history


@pytest.fixture(scope='module')
def room_bag(tmp_path_factory):
    clips = [walk_clip(40, name='walk_a'), wave_clip(40, name='wave_a', split='dev')]
    byname = {c.name: c for c in clips}
    out = tmp_path_factory.mktemp('rooms')
    spec = next(s for s in rooms_specs(clips, quick=True)
                if s.pan is None and '-empty-' in s.name)
    write_bag(spec, byname, out)
    bag = out / 'mcap' / spec.name
    with BagReader(bag) as reader:
        points = sum(len(gt) for _, gt in reader.frames() if gt is not None)
    return bag, points


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
