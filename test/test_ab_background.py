"""tools.ab_background: the static background timed against another checkout's, call for call."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tools import ab_background

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope='module')
def calls():
    return ab_background.record_calls('waving_two_hands', quick=True)


def test_this_checkout_against_itself(calls):
    names = {name for name, _, _ in calls}
    assert {'foreground', 'observe_color', 'protect'} <= names
    report = ab_background.compare(calls, ab_background.other_model(ROOT), repeats=2)
    assert report['timed'] == sum(name == 'foreground' for name, _, _ in calls)
    assert report['ratio'] > 0 and min(report['foreground_ms'].values()) > 0
    assert min(report['marks_ms'].values()) > 0


def test_a_model_with_other_masks_is_refused(calls, tmp_path):
    core = tmp_path / 'endeff_ros' / 'core'
    core.mkdir(parents=True)
    (core / 'background.py').write_text(
        'from endeff_ros.core.background import BackgroundModel as _Model\n\n\n'
        'class BackgroundModel(_Model):\n'
        '    def foreground(self, *args, **kwargs):\n'
        '        return ~super().foreground(*args, **kwargs)\n')
    with pytest.raises(AssertionError, match='masks differ'):
        ab_background.compare(calls, ab_background.other_model(tmp_path), repeats=1)


def test_main_writes_the_report(tmp_path, capsys):
    out = tmp_path / 'ab.json'
    assert ab_background.main([str(ROOT), '--quick', '--repeats', '2', '--no-pin', '--json',
                               str(out)]) == 0
    assert json.loads(out.read_text())['sequence'] == 'waving_two_hands'
