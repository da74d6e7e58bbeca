"""Average precision and calibration of the published confidence (endeff_ros.ranking)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from bag_helpers import BagSpec, FakeTracker, fake_estimate_frame, write_bag

from endeff_ros.evaluate import evaluate_bags, format_table, write_plots
from endeff_ros.ranking import (
    ConfidenceRanking,
    average_precision,
    calibration_bins,
    calibration_error,
    summary_json,
)


def test_average_precision_is_the_recall_when_right_ends_rank_first():
    conf = [0.9, 0.8, 0.7, 0.2, 0.1]
    right = [True, True, True, False, False]
    assert average_precision(conf, right, 4) == pytest.approx(0.75)


def test_average_precision_falls_when_a_wrong_end_outranks_the_right_ones():
    right = [True, True, True, False]
    good = average_precision([0.9, 0.8, 0.7, 0.1], right, 3)
    bad = average_precision([0.5, 0.4, 0.3, 0.9], right, 3)
    assert good == pytest.approx(1.0)
    # One false end first: precision 1/2, 2/3, 3/4 at the three right ends.
    assert bad == pytest.approx((1 / 2 + 2 / 3 + 3 / 4) / 3)


def test_equal_confidences_enter_together():
    """Ends of equal confidence cannot be told apart: the order they are listed in does not
    matter, and the AP is that of one threshold."""
    a = average_precision([1.0, 1.0, 1.0, 1.0], [True, False, True, False], 2)
    b = average_precision([1.0, 1.0, 1.0, 1.0], [False, False, True, True], 2)
    assert a == b == pytest.approx(0.5)


def test_average_precision_without_ground_truth_or_ends():
    assert math.isnan(average_precision([0.5], [False], 0))
    assert average_precision([], [], 3) == 0.0


def test_calibration_error_is_zero_for_frequencies_that_match_and_the_gap_otherwise():
    rng = np.random.default_rng(0)
    conf = np.repeat([0.25, 0.75], 4000)
    right = rng.random(len(conf)) < conf
    assert calibration_error(calibration_bins(conf, right)) < 0.03
    # Everything claimed at 0.95, right half of the time: 0.45 off.
    assert calibration_error(calibration_bins(np.full(100, 0.95), np.arange(100) < 50)) == \
        pytest.approx(0.45)


def test_a_ranking_counts_kinds_by_label_for_right_ends_and_by_published_kind_for_false():
    r = ConfidenceRanking()
    # Frame: labels head, hand; ends: 0 matched to the hand, 1 false published as a hand,
    # 2 false published as a head.
    r.add([0.9, 0.8, 0.1], [1, 2, 1], np.array([[0, 1]]), 2, np.array(['head', 'hand']))
    assert r.kind == ['hand', 'hand', 'head']
    assert r.average_precision('hand') == pytest.approx(1.0)
    assert r.average_precision('head') == 0.0
    assert r.average_precision() == pytest.approx(0.5)
    out = summary_json([r])
    assert out['kinds'] == {'head': 0.0, 'hand': 1.0}
    assert out['ends'] == 3


def test_eval_reports_average_precision_calibration_and_the_plot(tmp_path):
    """Through ``endeff eval``: the report's confidence section, its table and the plot. The
    fake tracker publishes 0.9 for every end, all right: AP is the recall and the ECE 0.1."""
    write_bag(tmp_path / 'seq', BagSpec(frames=6))
    report, _ = evaluate_bags([tmp_path / 'seq'], estimate_fn=fake_estimate_frame,
                              tracker_factory=FakeTracker)
    conf = report['confidence']
    recall = report['overall']['temporal']['recall']
    assert conf['average_precision'] == pytest.approx(recall, abs=1e-3)
    assert conf['calibration_error'] == pytest.approx(0.1, abs=1e-3)
    assert conf['pr_curve']['recall']
    assert report['sequences'][0]['confidence']['ends'] == conf['ends'] > 0
    assert 'confidence (temporal)' in format_table(report)
    written = write_plots(report, tmp_path / 'plots')
    assert tmp_path / 'plots' / 'confidence.png' in written
