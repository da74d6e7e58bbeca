"""tools.smoothing_replay: filters of the published positions scored on recorded tracks."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tools import smoothing_replay


def test_replayed_default_filter_is_what_the_tracker_published(room_bag):
    _, frames = smoothing_replay.record_bag(room_bag[0])
    steps = smoothing_replay.variants()
    shown = smoothing_replay.replay(frames, steps['one_euro_default'])
    published = [f[5] for f in frames]
    assert sum(len(p) for p in published) > 0
    for s, p in zip(shown, published, strict=True):
        np.testing.assert_allclose(s, p, atol=1e-6)
    # Unfiltered, the replay publishes the raw positions, and they differ from the filtered.
    raw = smoothing_replay.replay(frames, steps['raw'])
    assert max(float(np.abs(r - p).max(initial=0)) for r, p in zip(raw, published)) > 1e-3
    scores = smoothing_replay.score(frames, shown)
    assert 0 < scores['recall'] <= 1 and scores['jitter_m'] > 0


def _track(positions: np.ndarray, dt: float = 1 / 30) -> list[smoothing_replay.Frame]:
    """One track (id 0) at ``positions``, its truth the same points without noise."""
    return [(k, int(k * dt * 1e9), np.array([0]), p[None], np.array([True]), p[None],
             None, None, None, np.array([k == 0]), np.full((1, 3), np.nan))
            for k, p in enumerate(positions)]


def test_kalman_follows_constant_velocity_and_smooths_a_still_point():
    t = np.arange(60) / 30
    moving = np.stack([2.0 * t, np.zeros_like(t), np.full_like(t, 2.0)], axis=1)
    step = smoothing_replay.kalman_step(20.0, 0.01)
    out = np.concatenate(smoothing_replay.replay(_track(moving), step))
    assert np.abs(out[20:] - moving[20:]).max() < 0.005  # no lag once the velocity is known
    rng = np.random.default_rng(0)
    still = np.array([0.1, 0.2, 1.5]) + rng.normal(0, 0.01, (60, 3))
    # A small process noise trusts the motion model: a still point is held still.
    out = np.concatenate(smoothing_replay.replay(_track(still), smoothing_replay.kalman_step(
        0.1, 0.01)))
    assert (np.std(out[20:], axis=0) < 0.6 * np.std(still[20:], axis=0)).all()


def test_main_scores_every_variant(room_bag, tmp_path, capsys):
    record, report = tmp_path / 'tracks.pkl', tmp_path / 'filters.json'
    assert smoothing_replay.main(['collect', str(room_bag[0]), '--out', str(record)]) == 0
    assert smoothing_replay.main(['score', str(record), '--json', str(report)]) == 0
    figures = json.loads(report.read_text())
    assert set(figures) == set(smoothing_replay.variants())
    assert 'largest difference to the published' in capsys.readouterr().out


def test_jitter_is_split_by_how_far_the_truth_moved():
    """A still end whose detection alternates 1 cm either side shows 20 mm of jitter in the
    still bin; an end followed exactly while it moves shows none in its bin."""
    n = 30
    still = np.tile([0.0, 0.0, 2.0], (n, 1))
    moving = np.stack([0.5 + 0.03 * np.arange(n), np.zeros(n), np.full(n, 2.0)], axis=1)
    wobble = still + np.array([0.01, 0.0, 0.0]) * (-1.0) ** np.arange(n)[:, None]
    frames = [(k, int(k * 1e9 / 30), np.array([0, 1]), np.stack([wobble[k], moving[k]]),
               np.array([True, True]), np.stack([wobble[k], moving[k]]),
               np.stack([still[k], moving[k]]), np.array([7, 8]), np.array(['hand', 'hand']),
               np.array([k == 0, k == 0]), np.full((2, 3), np.nan)) for k in range(n)]
    shown = [f[3] for f in frames]
    split = smoothing_replay.jitter_by_truth_step(frames, shown)
    assert split['0-5 mm'] == (n - 1, pytest.approx(0.02))
    assert split['20-50 mm'] == (n - 1, pytest.approx(0.0))
    assert split['5-20 mm'][0] == 0 and split['50+ mm'][0] == 0
    # A gap in the recorded frames ends the pairs: no pair across it.
    gapped = frames[:10] + [(k + 5, *f[1:]) for k, f in enumerate(frames[10:], start=10)]
    assert smoothing_replay.jitter_by_truth_step(gapped, shown)['0-5 mm'][0] == n - 2
