"""Time-consistency figures of ``endeff eval`` on hand-made sequences with known answers."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from bag_helpers import BagSpec, FakeTracker, fake_estimate_frame, write_bag

from endeff_ros.evaluate import evaluate_bags, format_table
from endeff_ros.scoring import score_frame
from endeff_ros.tracking_metrics import TrackingScorer, mean_over_sequences

PERIOD_NS = 33_333_333  # 30 Hz


def _run(truth: np.ndarray, published: list[list[tuple[int, np.ndarray]]],
         kinds: list[str] | None = None) -> dict:
    """Score ``published[t]`` ([(track id, xyz)]) against ``truth[t]`` ((N, 3), row = id)."""
    scorer = TrackingScorer()
    for t, tracks in enumerate(published):
        pos = np.array([p for _, p in tracks], dtype=float).reshape(-1, 3)
        ids = [i for i, _ in tracks]
        score = score_frame(pos, truth[t])
        scorer.add(t * PERIOD_NS, truth[t], None, kinds, pos, ids, score.matches)
    return scorer.result()


def _still(n: int, *points: tuple[float, float, float]) -> np.ndarray:
    return np.repeat(np.array(points, dtype=float)[None], n, axis=0)


@pytest.mark.parametrize(('runs', 'switches', 'ids'), [
    ([(30, 1), (30, 1)], 0, 1),
    ([(10, 1), (20, 2), (30, 1)], 2, 2),
    ([(15, 1), (15, 2), (15, 3), (15, 4)], 3, 4),
])
def test_id_switches_per_minute_and_ids_per_end_effector(runs, switches, ids):
    truth = _still(60, (0.0, 0.0, 2.0))  # 60 frames at 30 Hz: 2 s = 1/30 min
    published = [[(track, truth[0, 0])] for n, track in runs for _ in range(n)]
    r = _run(truth, published)['all']
    assert r['id_switches'] == switches
    assert r['id_switches_per_min'] == pytest.approx(switches * 30)
    assert r['ids_per_end_effector'] == ids


def test_a_gap_without_match_is_no_switch_but_a_new_id_after_it_is():
    truth = _still(30, (0.0, 0.0, 2.0))
    same = [[(5, truth[0, 0])]] * 10 + [[]] * 10 + [[(5, truth[0, 0])]] * 10
    other = [[(5, truth[0, 0])]] * 10 + [[]] * 10 + [[(6, truth[0, 0])]] * 10
    assert _run(truth, same)['all']['id_switches'] == 0
    assert _run(truth, other)['all']['id_switches'] == 1


def test_a_track_too_far_away_is_no_match():
    truth = _still(10, (0.0, 0.0, 2.0))
    far = [[(1, truth[0, 0] + [0.2, 0, 0])]] * 5 + [[(2, truth[0, 0])]] * 5
    r = _run(truth, far)['all']
    assert r['ids_per_end_effector'] == 1 and r['id_switches'] == 0


def test_idf1_is_the_global_assignment_not_each_end_effectors_best_track():
    # End A: track 1 for 5 frames, then track 2 for 4; end B: nothing, then track 1 for 4.
    # Each end's best track (A -> 1: 5) gives IDTP 5; the one-to-one optimum A -> 2, B -> 1
    # gives 8.
    a, b = np.array([0.0, 0.0, 2.0]), np.array([1.0, 0.0, 2.0])
    truth = _still(9, a, b)
    published = ([[(1, a)]] * 5 + [[(2, a), (1, b)]] * 4)
    r = _run(truth, published)['all']
    assert (r['idtp'], r['idfn'], r['idfp']) == (8, 18 - 8, 13 - 8)
    assert r['idf1'] == pytest.approx(16 / (18 + 13))


def test_idf1_is_one_for_perfect_ids_and_counts_spurious_tracks():
    a, b = np.array([0.0, 0.0, 2.0]), np.array([1.0, 0.0, 2.0])
    truth = _still(10, a, b)
    assert _run(truth, [[(1, a), (2, b)]] * 10)['all']['idf1'] == 1.0
    spurious = [[(1, a), (2, b), (3, a + [0, 2.0, 0])]] * 10
    assert _run(truth, spurious)['all']['idf1'] == pytest.approx(40 / 50)


def test_jitter_is_the_change_of_the_error_not_a_constant_offset():
    truth = _still(20, (0.0, 0.0, 2.0))
    offset = [[(1, truth[0, 0] + [0.03, 0, 0])]] * 20
    noisy = [[(1, truth[0, 0] + [0.01 * (-1) ** t, 0, 0])] for t in range(20)]
    assert _run(truth, offset)['all']['jitter_m'] == pytest.approx(0.0)
    assert _run(truth, noisy)['all']['jitter_m'] == pytest.approx(0.02)


def test_jitter_skips_pairs_across_a_switch_or_a_gap():
    truth = _still(4, (0.0, 0.0, 2.0))
    g = truth[0, 0]
    # Frames 0-1 track 1 at +1 cm, frame 2 track 2 at -5 cm, frame 3 nothing: one pair, 0.
    r = _run(truth, [[(1, g + [0.01, 0, 0])], [(1, g + [0.01, 0, 0])],
                     [(2, g - [0.05, 0, 0])], []])['all']
    assert r['jitter_m'] == pytest.approx(0.0)


def test_acceleration_error_of_noise_on_a_moving_hand():
    n = 30
    truth = (np.array([0.0, 0.0, 2.0]) + np.arange(n)[:, None] * [0.05, 0, 0])[:, None]
    lagging = [[(1, truth[t, 0] - [0.02, 0, 0])] for t in range(n)]  # constant lag: exact
    noisy = [[(1, truth[t, 0] + [0.005 * (-1) ** t, 0, 0])] for t in range(n)]
    assert _run(truth, lagging)['all']['accel_error_m'] == pytest.approx(0.0, abs=1e-12)
    assert _run(truth, noisy)['all']['accel_error_m'] == pytest.approx(0.02)


def test_figures_per_kind():
    head, hand = np.array([0.0, -0.8, 2.0]), np.array([0.4, 0.0, 2.0])
    truth = _still(30, head, hand)
    published = [[(0, head), (1 + t // 10, hand)] for t in range(30)]  # the hand: 3 ids
    r = _run(truth, published, kinds=['head', 'hand'])
    assert r['head']['id_switches'] == 0 and r['head']['ids_per_end_effector'] == 1
    assert r['hand']['id_switches'] == 2 and r['hand']['ids_per_end_effector'] == 3
    assert r['hand']['idf1'] < r['head']['idf1'] == 1.0
    assert r['all']['id_switches'] == 2
    assert r['all']['ids_per_end_effector'] == 2


def test_mean_over_sequences_averages_figures_and_sums_counts():
    truth = _still(30, (0.0, 0.0, 2.0))
    one = _run(truth, [[(1, truth[0, 0])]] * 30)
    two = _run(truth, [[(1 + t // 15, truth[0, 0])] for t in range(30)])
    mean = mean_over_sequences([one, two])['all']
    assert mean['ids_per_end_effector'] == 1.5
    assert mean['id_switches'] == 1
    assert not math.isnan(mean['idf1'])


def test_eval_reports_the_figures_per_sequence_group_and_kind(tmp_path: Path) -> None:
    write_bag(tmp_path / 'seq', BagSpec(frames=8))
    report, _ = evaluate_bags([tmp_path / 'seq'], estimate_fn=fake_estimate_frame,
                              tracker_factory=FakeTracker)
    seq = report['sequences'][0]['tracking']
    assert {'id_switches_per_min', 'ids_per_end_effector', 'idf1', 'jitter_m',
            'accel_error_m', 'kinds'} <= set(seq)
    assert seq['end_effectors'] > 0
    assert report['tracking']['idf1'] == seq['idf1']
    table = format_table(report)
    assert 'time consistency' in table and 'IDF1' in table
