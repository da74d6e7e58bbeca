"""The candidate scorer (core/candidates.py): over-generation past the thresholds of Section 4,
the candidates' evidence, and the selection by the committed model's score."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest

from endeff_ros.core.candidates import (
    FEATURES,
    CandidateModel,
    candidate_features,
    committed_model,
)
from endeff_ros.core.confidence import NO_FLOOR
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.single_frame import estimate_frame
from endeff_ros.synth import scenes

COL = {n: i for i, n in enumerate(FEATURES)}
#: Over-generation with the thresholds deciding; low, so that clean scenes over-generate too.
OVER = EndeffParams(candidate_floor=0.04, candidate_scorer=False)
ALONE = EndeffParams(candidate_floor=0.0)  # the thresholds of Section 4 alone


@functools.cache
def _shot(kind: str):
    if kind == 'star':
        return scenes.shoot(scenes.star(5, spin=0.3), scenes.LEVEL, floor=False)
    pose = 'arms_down' if kind == 'arms_down' else 't_pose'
    return scenes.shoot(scenes.person(pose, yaw=0.4), scenes.LEVEL, floor=True)


@pytest.mark.parametrize('kind', ['person', 'arms_down'])
def test_over_generation_with_the_thresholds_deciding_changes_no_candidate(kind: str) -> None:
    frame = _shot(kind).frame
    alone = estimate_frame(frame, ALONE)
    over = estimate_frame(frame, OVER)
    assert alone.scored is None
    np.testing.assert_array_equal(over.positions(), alone.positions())
    scored = over.scored
    assert scored is not None
    # Every candidate the thresholds keep is among the over-generated ones, flagged as kept.
    assert np.array_equal(scored.kept, scored.features[:, COL['thresholds']] > 0.5)
    np.testing.assert_array_equal(scored.positions[scored.kept], alone.positions())
    assert len(scored.kept) > scored.kept.sum(), 'nothing was over-generated'
    # What the thresholds drop protrudes at least the floor, or is a broad corner or cut.
    dropped = scored.features[~scored.kept]
    assert np.all((dropped[:, COL['protrusion']] >= OVER.candidate_floor - 1e-9)
                  | (dropped[:, COL['broad']] > 0) | (dropped[:, COL['cut']] > 0))


def test_candidate_features() -> None:
    for kind in ('person', 'star'):
        est = estimate_frame(_shot(kind).frame, OVER)
        f = candidate_features(est, _shot(kind).frame.intrinsics)
        assert f.shape == (len(est.positions()), len(FEATURES))
        assert np.all(np.isfinite(f))
        for name in ('thresholds', 'broad', 'cut'):
            assert set(np.unique(f[:, COL[name]])) <= {0.0, 1.0}
        assert np.all((f[:, COL['nearest']] > 0) & (f[:, COL['nearest']] <= 1.0))
        per_entity = [len(e.candidates) for e in est.entities if e.candidates]
        np.testing.assert_array_equal(f[:, COL['count']],
                                      np.repeat(np.minimum(per_entity, 12), per_entity))
        assert np.all(f[:, COL['order']] == np.concatenate([np.arange(n) for n in per_entity]))
    # The star floats with no floor in view: its height is the "no floor" sentinel.
    star = estimate_frame(_shot('star').frame, OVER)
    assert np.all(candidate_features(star)[:, COL['height']] == NO_FLOOR)


def test_the_scorer_keeps_the_candidates_its_score_admits() -> None:
    """A candidate the thresholds pass over needs ``min_candidate_score``; one they keep is
    dropped only below ``drop_candidate_score``."""
    frame = _shot('arms_down').frame
    everything = estimate_frame(frame, OVER).scored
    by_thresholds = everything.kept
    assert by_thresholds.any() and not by_thresholds.all()
    scorer = dataclasses.replace(OVER, candidate_scorer=True)
    score = committed_model()(everything.features)
    assert np.all((score > 0) & (score < 1))
    cuts = (0.0, float(np.median(score)), 1.0)
    for least in cuts:
        for drop in cuts:
            est = estimate_frame(frame, dataclasses.replace(
                scorer, min_candidate_score=least, drop_candidate_score=drop))
            want = np.where(by_thresholds, score >= drop, score >= least)
            np.testing.assert_array_equal(est.positions(), everything.positions[want])
            kept = [c for e in est.entities for c in e.candidates]
            np.testing.assert_allclose([c.score for c in kept], score[want])


def test_the_committed_model_reads_and_scores_every_feature() -> None:
    model = CandidateModel.load()
    assert set(model.names) == set(FEATURES)
    assert all(np.all(np.isfinite(w)) for w in model.weights)
    with pytest.raises(ValueError, match='candidate model'):
        CandidateModel.from_json({'bias': 0.0, 'features': [
            {'name': 'no such feature', 'edges': [], 'weights': [0.0]}]})



def test_train_candidates_collects_every_candidate_and_fits_a_model(tmp_path) -> None:
    """``tools.train_candidates collect`` on a quick bag: one row per over-generated candidate
    of each annotated frame, right where the frame's matching of all of them made it a true
    positive, the thresholds' verdict beside it; ``fit`` writes a model that loads and whose
    report compares it with the thresholds."""
    import json

    from endeff_ros.synth import cli as synth_cli
    from tools.train_candidates import load, main

    synth_cli.generate_one('punching', tmp_path, ['mcap'], True, 0)
    assert main(['collect', str(tmp_path / 'mcap'), '--out', str(tmp_path / 'c')]) == 0
    (bag,) = load([tmp_path / 'c'])
    assert len(bag['features']) == len(bag['right']) == len(bag['kept']) == len(
        bag['positions']) > 0
    assert bag['features'].shape[1] == len(FEATURES)
    assert 0 < bag['right'].sum() < len(bag['right'])  # premise: right and wrong candidates
    assert (bag['features'][:, COL['thresholds']] > 0.5).tolist() == bag['kept'].tolist()
    assert len(bag['gt']) == len(bag['gt_frame']) and bag['frames'] > 0
    model = tmp_path / 'm.json'
    assert main(['fit', str(tmp_path / 'c'), '--model', str(model), '--json',
                 str(tmp_path / 'r.json')]) == 0
    assert set(CandidateModel.load(model).names) == set(FEATURES)
    report = json.loads((tmp_path / 'r.json').read_text(encoding='utf-8'))
    assert report['candidates'] == len(bag['right'])
    assert report['operating_points'][0]['keep'] == 'thresholds'


def test_holdout_reports_each_half_of_the_clips_with_the_other_halfs_model() -> None:
    """``--holdout`` of the fitting tools (``additive_fit.holdout_report``): no clip is both
    fitted and reported on, and every bag is reported once."""
    from tools import additive_fit

    bags = [{'name': f'dev__clip{c}__{v}-view-abcdef12'} for c in range(8) for v in range(3)]

    def clips(sel: list[dict]) -> set[str]:
        return {b['name'].split('__')[1] for b in sel}

    out = additive_fit.holdout_report(bags, lambda train: clips(train),
                                      lambda held, fitted: {'held': clips(held), 'n': len(held),
                                                            'fitted': fitted})
    folds = out['folds']
    assert [f['held_out_fold'] for f in folds] == [0, 1]
    assert sum(f['n'] for f in folds) == len(bags)
    for f in folds:
        assert f['held'] and f['fitted'] and not f['held'] & f['fitted']
