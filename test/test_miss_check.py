"""tools.miss_check: every ground-truth point and reported end-effector in one class."""

from __future__ import annotations

import dataclasses

import pytest

from endeff_ros.core.params import EndeffParams
from tools import miss_check


def test_every_point_gets_one_class(room_bag):
    bag, points = room_bag
    r = miss_check.check_bag(bag)
    assert sum(r['ground_truth'].values()) == points
    assert r['ground_truth']['found'] > 0
    assert r['reported']['tp'] > 0
    # The same points per kind: a person's head, hands and feet, from the ground-truth ids.
    kinds = r['ground_truth_by_kind']
    assert set(kinds) == {'head', 'hand', 'foot'}
    for cls in miss_check.GT_CLASSES:
        assert sum(k[cls] for k in kinds.values()) == r['ground_truth'][cls]


def test_an_end_moved_off_its_part_is_a_near_miss(room_bag, monkeypatch):
    """Every reported end shifted 0.2 m sideways: what was found becomes a near miss."""
    bag, _ = room_bag
    found = miss_check.check_bag(bag)['ground_truth']['found']
    update = miss_check.Tracker.update

    def shifted(self, frame, *args, **kwargs):
        result = update(self, frame, *args, **kwargs)
        for t in result.tracks:
            t.position[0] += 0.2
        return result

    monkeypatch.setattr(miss_check.Tracker, 'update', shifted)
    r = miss_check.check_bag(bag)['ground_truth']
    assert r['found'] < found / 4
    assert r['near_miss'] > found / 2


def test_a_box_that_holds_nothing_puts_every_point_outside_it(room_bag):
    bag, points = room_bag
    params = dataclasses.replace(EndeffParams(), box_min_z=0.4, box_max_z=0.5)
    r = miss_check.check_bag(bag, params)
    assert r['ground_truth']['outside_box'] == points
    assert sum(r['reported'].values()) == 0


def test_report_shares_and_refuses_an_empty_folder(room_bag, tmp_path, capsys):
    bag, _ = room_bag
    assert miss_check.main([str(bag.parent), '--json', str(tmp_path / 'r.json')]) == 0
    report = (tmp_path / 'r.json').read_text()
    assert '"outside_box"' in report and '"fp_far"' in report
    with pytest.raises(SystemExit) as exc:
        miss_check.main([str(tmp_path / 'none')])
    assert exc.value.code == 2
    assert 'no bags' in capsys.readouterr().err
