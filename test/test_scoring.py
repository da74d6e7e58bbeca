"""Section 6.1 scoring (Eqs. 10-12) on hand-computed cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from endeff_ros.scoring import (
    KindScore,
    MethodScore,
    SequenceScorer,
    kinds_of_ids,
    mean_kinds_over_sequences,
    mean_over_sequences,
    score_frame,
    score_sequence,
    seen_labels,
)


def test_perfect_frame() -> None:
    gt = np.array([[0.0, 0.0, 2.0], [0.5, 0.0, 2.0], [0.0, 0.5, 2.0]])
    s = score_frame(gt + [0.0, 0.0, 0.03], gt)
    assert (s.tp, s.fp, s.n_gt, s.n_est) == (3, 0, 3, 3)
    assert s.recall == 1.0 and s.fpr == 0.0
    np.testing.assert_allclose(s.errors, [0.03, 0.03, 0.03])


def test_threshold_is_inclusive_and_misses_are_fp() -> None:
    gt = np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 2.0]])
    # First estimate exactly 0.15 m away (TP), second 0.2 m away (matched but FP), third extra.
    est = np.array([[0.15, 0.0, 2.0], [1.0, 0.2, 2.0], [5.0, 5.0, 5.0]])
    s = score_frame(est, gt)
    assert s.tp == 1 and s.fp == 2
    assert s.recall == pytest.approx(0.5)
    assert s.fpr == pytest.approx(2 / 3)
    np.testing.assert_allclose(s.errors, [0.15])
    assert s.matches.tolist() == [[0, 0]]


def test_one_to_one_matching() -> None:
    # Two estimates near the same GT point: only one can match it.
    gt = np.array([[0.0, 0.0, 2.0]])
    est = np.array([[0.0, 0.0, 2.05], [0.0, 0.0, 2.01]])
    s = score_frame(est, gt)
    assert s.tp == 1 and s.fp == 1
    assert s.recall == 1.0 and s.fpr == 0.5
    np.testing.assert_allclose(s.errors, [0.01])


def test_hungarian_minimises_total_distance() -> None:
    # Greedy nearest-first would pair e0-g1 (0.05) and leave e1-g0 at 0.30 (one TP); the
    # minimum-total assignment pairs e0-g0 (0.10) and e1-g1 (0.10): two TPs.
    gt = np.array([[0.0, 0.0, 0.0], [0.15, 0.0, 0.0]])
    est = np.array([[0.10, 0.0, 0.0], [0.25, 0.0, 0.0]])
    s = score_frame(est, gt)
    assert s.tp == 2
    np.testing.assert_allclose(sorted(s.errors), [0.10, 0.10])


def test_empty_cases() -> None:
    gt = np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 2.0]])
    none = score_frame(np.zeros((0, 3)), gt)
    assert none.recall == 0.0 and none.fpr == 0.0  # Eq. 12: 0 when nothing is estimated
    no_gt = score_frame(gt, np.zeros((0, 3)))
    assert math.isnan(no_gt.recall) and no_gt.fpr == 1.0
    assert score_frame(None, gt).n_est == 0


def test_bad_input_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match='non-finite'):
        score_frame([[np.nan, 0.0, 1.0]], [[0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match=r'\(N, 3\)'):
        score_frame([[0.0, 1.0]], [[0.0, 0.0, 1.0]])


def test_sequence_means() -> None:
    gt = np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 2.0]])
    scorer = SequenceScorer()
    # Frame 1: both found (errors 0.02, 0.04) -> recall 1, FPR 0.
    scorer.add(gt + [[0.02, 0, 0], [0.04, 0, 0]], gt)
    # Frame 2: one found (error 0.06) plus one FP -> recall 0.5, FPR 0.5.
    scorer.add([[0.06, 0.0, 2.0], [3.0, 3.0, 3.0]], gt)
    # Frame 3: not annotated -> processed, not scored.
    scorer.add([[9.0, 9.0, 9.0]], None)
    # Frame 4: nothing estimated -> recall 0, FPR 0.
    scorer.add(np.zeros((0, 3)), gt)
    r = scorer.result()
    assert scorer.frames == 4 and scorer.scored_frames == 3
    assert r.recall == pytest.approx((1 + 0.5 + 0) / 3)
    assert r.fpr == pytest.approx((0 + 0.5 + 0) / 3)
    # Eq. 11 over all TP pairs, not the mean of per-frame means.
    assert r.mean_error_m == pytest.approx((0.02 + 0.04 + 0.06) / 3)
    assert scorer.tp == 3


def test_score_sequence_and_overall() -> None:
    gt = [[[0.0, 0.0, 1.0]]] * 2
    a = score_sequence([[[0.0, 0.0, 1.1]], [[0.0, 0.0, 1.5]]], gt)
    assert a.recall == pytest.approx(0.5) and a.fpr == pytest.approx(0.5)
    assert a.mean_error_m == pytest.approx(0.1)
    b = MethodScore(recall=1.0, mean_error_m=math.nan, fpr=0.0)
    overall = mean_over_sequences([a, b])
    assert overall.recall == pytest.approx(0.75)
    assert overall.fpr == pytest.approx(0.25)
    assert overall.mean_error_m == pytest.approx(0.1)  # undefined values are left out
    assert b.to_json() == {'recall': 1.0, 'mean_error_m': None, 'fpr': 0.0}
    with pytest.raises(ValueError):
        score_sequence([None], [None, None])


def test_kinds_of_ids() -> None:
    ids = np.array([0, 1, 2, 3, 4, 5, 7, 9], np.uint32)
    assert kinds_of_ids(ids, person=True).tolist() == [
        'head', 'hand', 'hand', 'foot', 'foot', 'head', 'hand', 'foot']
    assert kinds_of_ids(ids, person=False).tolist() == ['other'] * 8
    with pytest.raises(ValueError, match='non-negative integers'):
        kinds_of_ids([-1, 0], person=True)


def test_kind_recall_follows_the_frame_assignment() -> None:
    gt = np.array([[0.0, 0.0, 2.0], [0.12, 0.0, 2.0], [0.0, 1.0, 2.0]])
    kinds = np.array(['head', 'hand', 'foot'])
    scorer = SequenceScorer()
    # Frame 1: one estimate between head and hand, 0.06 m from each; the assignment gives it to
    # one of them only; the foot is found 0.02 m off.
    s1 = scorer.add([[0.06, 0.0, 2.0], [0.0, 1.02, 2.0]], gt, kinds)
    assert s1.tp == 2
    # Frame 2: only the hand, 0.04 m off, plus a false positive.
    scorer.add([[0.12, 0.04, 2.0], [3.0, 3.0, 3.0]], gt, kinds)
    # Frame 3: annotated without kinds: scored, left out of the kinds.
    scorer.add(gt, gt)
    got = scorer.kind_result()
    assert list(got) == ['head', 'hand', 'foot']
    head_hits = int(s1.matches[0, 1] == 0 or s1.matches[1, 1] == 0)
    assert got['head'].gt_points == 2 and got['head'].tp == head_hits
    assert got['hand'].tp == 2 - head_hits
    assert got['head'].recall + got['hand'].recall == pytest.approx(0.5 + 0.5)
    assert got['foot'].recall == pytest.approx(0.5)
    assert got['foot'].mean_error_m == pytest.approx(0.02)
    assert got['hand'].mean_error_m == pytest.approx(0.04 if head_hits else 0.05)
    assert scorer.result().recall == pytest.approx((2 / 3 + 1 / 3 + 1) / 3)
    with pytest.raises(ValueError, match='2 kinds given for 3'):
        scorer.add(gt, gt, kinds[:2])


def test_kind_means_over_sequences() -> None:
    a = {'head': KindScore(1.0, 0.02, 4, 4), 'hand': KindScore(0.5, math.nan, 4, 0)}
    b = {'hand': KindScore(0.0, math.nan, 2, 0), 'other': KindScore(1.0, 0.05, 3, 3)}
    got = mean_kinds_over_sequences([a, b])
    assert list(got) == ['head', 'hand', 'other']
    assert got['hand'].recall == pytest.approx(0.25)  # mean over the two sequences with hands
    assert math.isnan(got['hand'].mean_error_m)
    assert (got['hand'].gt_points, got['hand'].tp) == (6, 0)
    assert got['head'].recall == 1.0 and got['other'].mean_error_m == 0.05
    assert got['hand'].to_json()['mean_error_m'] is None


def _plane_depth(z: float = 2.0) -> tuple[np.ndarray, object]:
    """A 160x120 depth image of a wall at ``z`` m, with a 40x40 px hole (NaN) in its centre."""
    from endeff_ros.core.types import Intrinsics

    k = Intrinsics(200.0, 200.0, 79.5, 59.5, 160, 120)
    depth = np.full((120, 160), z, np.float32)
    depth[40:80, 60:100] = np.nan
    return depth, k


def test_seen_labels_need_readings_near_them() -> None:
    """Seen: readings within 0.1 m. On the wall and 0.08 m behind it: seen; 0.2 m behind it,
    in the hole, beyond the image or behind the camera: not."""
    depth, k = _plane_depth()
    labels = np.array([[-0.5, 0.2, 2.0],    # on the wall
                       [-0.5, 0.2, 2.08],   # a part centre behind its surface
                       [-0.5, 0.2, 2.2],    # hidden behind the wall
                       [0.0, 0.0, 2.0],     # in the hole: no reading within 0.1 m
                       [3.0, 0.0, 2.0],     # projects outside the image
                       [0.0, 0.0, -1.0],    # behind the camera
                       [np.inf, 0.0, 2.0]])  # not a position (scoring rejects it later)
    assert seen_labels(labels, depth, k).tolist() == [True, True, False, False, False, False,
                                                      False]
    # Near the hole's edge (0.05 m in x at 2 m = 5 px inside it) readings lie within 0.1 m.
    assert seen_labels([[0.15, 0.0, 2.0]], depth, k).tolist() == [True]
    assert seen_labels([[0.15, 0.0, 2.0]], depth, k, radius=0.04).tolist() == [False]
    assert seen_labels(np.zeros((0, 3)), depth, k).shape == (0,)


def test_a_few_stray_readings_are_not_seen() -> None:
    depth, k = _plane_depth()
    depth[:] = np.nan
    depth[59, 79:81] = 2.0  # two readings next to the label
    assert seen_labels([[0.0, 0.0, 2.0]], depth, k).tolist() == [False]
    depth[60, 79] = 2.0     # a third one
    assert seen_labels([[0.0, 0.0, 2.0]], depth, k).tolist() == [True]


def test_recall_over_the_seen_points() -> None:
    gt = np.array([[0.0, 0.0, 2.0], [0.5, 0.0, 2.0], [0.0, 1.0, 2.0]])
    kinds = np.array(['head', 'hand', 'hand'])
    scorer = SequenceScorer()
    # The head (seen) found, the seen hand missed, the unseen hand found (predicted).
    scorer.add([[0.0, 0.0, 2.0], [0.0, 1.0, 2.0]], gt, kinds, [True, True, False])
    scorer.add([], gt, kinds, [True, False, False])   # nothing found
    scorer.add(gt, gt, kinds)                          # no seen flags: left out
    assert (scorer.seen_points, scorer.seen_tp) == (3, 1)
    assert scorer.seen_recall == pytest.approx(1 / 3)
    got = scorer.kind_result()
    assert (got['head'].seen_points, got['head'].seen_tp) == (2, 1)
    assert (got['hand'].seen_points, got['hand'].seen_tp) == (1, 0)
    assert got['hand'].seen_recall == 0.0 and got['hand'].recall == pytest.approx(3 / 6)
    assert got['hand'].to_json()['seen_recall'] == 0.0
    assert math.isnan(SequenceScorer().seen_recall)
    with pytest.raises(ValueError, match='2 seen flags given for 3'):
        scorer.add(gt, gt, kinds, [True, True])
