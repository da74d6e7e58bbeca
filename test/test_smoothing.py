"""One Euro filter of the published positions, and the velocity: on the filter alone and on
painted scenes through the tracker."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
import scenarios as sc

from endeff_ros.core.params import EndeffParams
from endeff_ros.core.smoothing import OneEuroParams, one_euro
from endeff_ros.core.tracker import Tracker

DT = 1 / 30
DEFAULTS = EndeffParams()
FILTER = OneEuroParams(DEFAULTS.smoothing_min_cutoff, DEFAULTS.smoothing_beta,
                       DEFAULTS.smoothing_d_cutoff)  # unbounded: the filter's own lag


def _filter(raw: np.ndarray, params: OneEuroParams = FILTER) -> tuple[np.ndarray, np.ndarray]:
    """Filter an (F, N, 3) sequence sampled every DT; returns positions and velocities."""
    out, vel = [raw[0]], [np.zeros_like(raw[0])]
    for k in range(1, len(raw)):
        x, v = one_euro(raw[k], raw[k - 1], out[-1], vel[-1], DT, params)
        out.append(x)
        vel.append(v)
    return np.array(out), np.array(vel)


def test_a_hand_at_2_m_s_trails_by_at_most_3_cm():
    t = np.arange(60) * DT
    raw = (np.array([0.0, 0.0, 2.0]) + t[:, None] * [2.0, 0.0, 0.0])[:, None]
    out, vel = _filter(raw)
    lag = np.linalg.norm(out - raw, axis=2)[30:]
    assert lag.max() <= 0.03
    assert lag.min() > 0.001  # a low-pass trails: the bound is what is tested


def test_velocity_of_a_constant_velocity_point_with_noise():
    rng = np.random.default_rng(0)
    truth = np.array([0.7, -0.3, 0.2])
    t = np.arange(90) * DT
    raw = (t[:, None] * truth + rng.normal(0, 0.005, (90, 3)))[:, None]
    _, vel = _filter(raw)
    err = np.linalg.norm(vel[45:, 0] - truth, axis=1)
    assert err.max() < 0.2
    assert np.all(vel[0] == 0)


def test_a_still_noisy_point_varies_less_than_5_mm():
    rng = np.random.default_rng(1)
    raw = rng.normal(0, 0.003, (60, 1, 3))  # a part centre: about 3 mm
    out, _ = _filter(raw)
    spread = np.ptp(out[30:, 0], axis=0).max()
    assert np.ptp(raw[30:, 0], axis=0).max() > 0.01  # premise: the raw point jumps
    assert spread < 0.005


def test_lag_is_bounded_and_a_jump_restarts_the_filter():
    raw = np.array([[[0.0, 0.0, 2.0]]] * 10 + [[[0.1, 0.0, 2.0]]] * 3 + [[[0.6, 0, 2.0]]] * 2)
    bounded = FILTER._replace(max_lag=0.02, reset_distance=0.3)
    out, vel = _filter(raw, bounded)
    assert np.linalg.norm(out - raw, axis=2).max() <= 0.02 + 1e-12
    assert np.linalg.norm(out[10] - raw[10]) == pytest.approx(0.02)  # the bound held it
    assert np.allclose(out[13], raw[13]) and np.all(vel[13] == 0)  # 0.5 m: restarted
    free, _ = _filter(raw)
    assert np.linalg.norm(free[10] - raw[10]) > 0.02


# -- Through the tracker, on painted frames (depth only: zero-motion prediction) ----------------

R_HAND = 2  # ground-truth order of scenarios.person


@functools.cache
def _walk(speed: float, n: int) -> list[sc.Shot]:
    """A person with the right arm out sliding sideways at ``speed`` m/s (x: the body's
    left, the camera's right)."""
    return [sc.shoot(sc.person(sc.ARM_OUT, x=-0.8 + speed * k * DT), k) for k in range(n)]


@functools.cache
def _still_shots() -> list[sc.Shot]:
    return sc.still(sc.ARM_OUT, n=1)


def _params(**changes: object) -> EndeffParams:
    return EndeffParams(background=False, **changes)


def _hand_track(tracker_results, shots, k):
    tracks = tracker_results[k].tracks
    d = [np.linalg.norm(t.position - shots[k].gt[R_HAND]) for t in tracks]
    return tracks[int(np.argmin(d))]


def test_tracker_velocity_and_lag_of_a_hand_moving_at_2_m_s():
    shots = _walk(2.0, 45)
    tracker = Tracker(_params())
    results = [tracker.update(s.frame) for s in shots]
    truth_v = (shots[-1].gt[R_HAND] - shots[0].gt[R_HAND]) / ((len(shots) - 1) * DT)
    assert np.linalg.norm(truth_v) == pytest.approx(2.0, abs=0.05)  # premise
    first = _hand_track(results, shots, 0)
    assert np.all(first.velocity == 0)
    for k in range(30, len(shots)):  # after a second: the velocity's low-pass has settled
        t = _hand_track(results, shots, k)
        assert np.linalg.norm(t.velocity - truth_v) < 0.2, (k, t.velocity)
        lag = (np.linalg.norm(t.position - shots[k].gt[R_HAND])
               - np.linalg.norm(t.raw_position - shots[k].gt[R_HAND]))
        assert lag <= 0.03, (k, lag)


def test_tracker_still_hand_varies_less_than_5_mm_over_a_second_of_noisy_frames():
    shot = _still_shots()[0]
    rng = np.random.default_rng(2)
    tracker = Tracker(_params())
    published, raw = [], []
    for k in range(60):
        depth = shot.frame.depth + rng.normal(0, 0.01, shot.frame.depth.shape).astype(np.float32)
        frame = dataclasses.replace(shot.frame, depth=depth, stamp_ns=k * sc.PERIOD_NS)
        tracks = tracker.update(frame).tracks
        t = min(tracks, key=lambda t: np.linalg.norm(t.position - shot.gt[R_HAND]))
        if k >= 30:
            published.append(t.position)
            raw.append(t.raw_position)
            assert np.linalg.norm(t.position - shot.gt[R_HAND]) < 0.15
    assert np.ptp(np.array(raw), axis=0).max() > 0.005  # premise: the detections jitter
    assert np.ptp(np.array(published), axis=0).max() < 0.005


def test_smoothing_off_publishes_the_raw_position():
    shots = _walk(2.0, 45)[:6]
    tracker = Tracker(_params(smoothing=False))
    for s in shots:
        for t in tracker.update(s.frame).tracks:
            assert np.array_equal(t.position, t.raw_position)
