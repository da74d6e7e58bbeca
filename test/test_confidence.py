"""The scored confidence (endeff_ros.core.confidence), its model file and min_confidence."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scenarios as sc

from endeff_ros.core.confidence import FEATURES, MODEL_FILE, ConfidenceModel
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.tracker import Tracker
from tools.train_confidence import fit


def _model(weights: dict[str, tuple[list[float], list[float]]], bias: float = 0.0) -> dict:
    return {'bias': bias, 'features': [{'name': n, 'edges': e, 'weights': w}
                                       for n, (e, w) in weights.items()]}


def test_the_model_adds_one_weight_per_feature_interval():
    model = ConfidenceModel.from_json(_model({'age': ([1.0, 2.0], [-1.0, 0.0, 2.0]),
                                              'detected': ([0.5], [-3.0, 1.0])}, bias=0.5))
    x = np.zeros((3, len(FEATURES)))
    x[:, FEATURES.index('age')] = [0.5, 1.5, 3.0]
    x[:, FEATURES.index('detected')] = [1, 0, 1]
    np.testing.assert_allclose(model.logit(x), [0.5 - 1 + 1, 0.5 + 0 - 3, 0.5 + 2 + 1])
    assert np.all((model(x) > 0) & (model(x) < 1))


@pytest.mark.parametrize(('bad', 'why'), [
    ({'features': []}, 'missing'),
    (_model({'elbow_angle': ([0.5], [0.0, 1.0])}), 'unknown features'),
    (_model({'age': ([0.5, 1.0], [0.0, 1.0])}), '2 edges and 2 weights'),
])
def test_a_malformed_model_is_refused_with_what_is_wrong(bad, why):
    with pytest.raises(ValueError, match=why):
        ConfidenceModel.from_json(bad)


def test_an_unreadable_model_file_is_one_error_naming_it(tmp_path):
    with pytest.raises(ValueError, match='nowhere.json'):
        ConfidenceModel.load(tmp_path / 'nowhere.json')
    broken = tmp_path / 'broken.json'
    broken.write_text('{"bias": ', encoding='utf-8')
    with pytest.raises(ValueError, match='broken.json'):
        ConfidenceModel.load(broken)


def test_the_committed_model_loads_and_covers_every_feature():
    data = json.loads(MODEL_FILE.read_text(encoding='utf-8'))
    model = ConfidenceModel.from_json(data)
    assert set(model.names) == set(FEATURES)


def test_fit_recovers_a_feature_that_decides_and_is_calibrated():
    """On ends where the nearest other end decides (right beyond 0.25 m 90 % of the time,
    within it 10 %), the fitted model ranks by it and its probabilities match. Enough ends
    that the penalty on neighbouring intervals (which smooths the step at 0.25) is small
    against their likelihood."""
    rng = np.random.default_rng(1)
    x = rng.random((60000, len(FEATURES)))
    near = x[:, FEATURES.index('nearest_end')] < 0.25
    right = rng.random(len(x)) < np.where(near, 0.1, 0.9)
    model = fit(x, right)
    p = model(x)
    assert p[near].mean() == pytest.approx(0.1, abs=0.03)
    assert p[~near].mean() == pytest.approx(0.9, abs=0.03)


def test_min_confidence_hides_ends_but_keeps_tracking_them():
    """Ends below ``min_confidence`` are not published, yet their tracks go on: the ends
    shown are exactly those of the unfiltered run at or above it, with the same ids (the
    filter is on the output only)."""
    shots = sc.hand_to_side(5, 8)
    base = dict(background=False, scored_confidence=True)
    tracker = Tracker(EndeffParams(**base))
    every = [tracker.update(s.frame) for s in shots]
    confs = [t.confidence for r in every for t in r.tracks]
    assert np.ptp(confs) > 0  # premise: the scores differ
    threshold = float(np.median(confs))
    tracker = Tracker(EndeffParams(**base, min_confidence=threshold))
    shown = [tracker.update(s.frame) for s in shots]
    for a, b in zip(every, shown, strict=True):
        assert [(t.id, t.confidence) for t in b.tracks] == [
            (t.id, t.confidence) for t in a.tracks if t.confidence >= threshold]
    assert sum(len(a.tracks) for a in every) > sum(len(b.tracks) for b in shown) > 0


def test_collect_keeps_every_end_of_every_annotated_frame_and_score_reports_it(room_bag,
                                                                               tmp_path):
    """``tools.train_confidence collect`` on a rooms bag with a walking person: one row of
    evidence per published end of each annotated frame, right where the frame's matching
    made it a true positive; ``score`` reports the model and the paper's weight on it."""
    from tools.train_confidence import load, main

    bag, points = room_bag
    assert main(['collect', str(bag), '--out', str(tmp_path / 'c')]) == 0
    data = load([tmp_path / 'c'])
    assert data['n_gt'].sum() == points
    assert len(data['features']) == len(data['right']) == len(data['frame']) > 0
    assert data['features'].shape[1] == len(FEATURES)
    assert 0 < data['right'].sum() < len(data['right'])  # premise: right and wrong ends
    assert main(['score', str(tmp_path / 'c'), '--json', str(tmp_path / 'r.json')]) == 0
    report = json.loads((tmp_path / 'r.json').read_text(encoding='utf-8'))
    assert 0.0 <= report['model']['average_precision'] <= 1.0
    assert report['ends'] == len(data['right'])


def test_the_candidate_scores_along_a_track_are_evidence():
    """Each published end carries the candidate scorer's chance for the candidate that last
    supported its track and the mean over its supporting candidates: on a hand moved to the
    side both lie in (0, 1], the mean is a mean of the last ones seen, and without the scorer
    (``candidate_floor`` 0) both are 1."""
    shots = sc.hand_to_side(5, 8)
    col = FEATURES.index('candidate_score'), FEATURES.index('score_mean')
    tracker = Tracker(EndeffParams(background=False))
    last: dict[int, list[float]] = {}
    for s in shots:
        tracks = tracker.update(s.frame).tracks
        f = tracker.features
        for t, row in zip(tracks, f, strict=True):
            assert 0 < row[col[0]] <= 1 and 0 < row[col[1]] <= 1
            if t.state == 0:
                seen = last.setdefault(t.id, [])
                seen.append(row[col[0]])
                assert min(seen) - 1e-9 <= row[col[1]] <= max(seen) + 1e-9
    assert any(len(v) > 2 and np.ptp(v) > 0 for v in last.values())  # premise: scores vary
    tracker = Tracker(EndeffParams(background=False, candidate_floor=0.0))
    for s in shots:
        tracker.update(s.frame)
    assert len(tracker.features) and np.all(tracker.features[:, list(col)] == 1.0)
