"""Filters of the published positions compared on recorded tracks, without running the pipeline.

The tracker follows the raw positions (:mod:`endeff_ros.core.smoothing`): the filter changes
what is published, never which tracks there are. So one recorded run per bag (every track's
raw position, id and published flag per frame, with the ground truth) is enough to score any
filter: each replayed along the tracks, its published positions matched to the truth as
``endeff eval`` matches them (Hungarian within 0.15 m) and scored with
:class:`~endeff_ros.tracking_metrics.TrackingScorer` (jitter, acceleration error) and the
paper's recall and mean error.

    python -m tools.smoothing_replay collect BAG_OR_DIR [...] --out FILE.pkl [--jobs 2]
                                     [--params YAML]
    python -m tools.smoothing_replay score FILE.pkl [--json OUT]

``score`` replays the default One Euro filter first and checks that it gives the positions
the tracker published (the replay is faithful), then the variants of :func:`variants`, and
splits the raw and the default filter's jitter by how far the truth moved
(:func:`jitter_by_truth_step`).
"""

from __future__ import annotations

import argparse
import math
import pickle
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from endeff_ros.cli_common import load_params_option, print_json
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.smoothing import OneEuroParams, one_euro
from endeff_ros.scoring import score_frame
from endeff_ros.tracking_metrics import TrackingScorer
from tools.per_bag import run_per_bag
from tools.track_history import _RecordingTracker, tracked_frames

#: One recorded frame: index, stamp (ns), every track's id, raw position and published flag,
#: the positions published, the truth with its keys and kinds (None: no truth), which
#: tracks are new in the frame (a revived id is a new track: its filter starts again) and
#: each track's motion since the frame before by the scene flow (its anchor's prediction,
#: :meth:`Tracker._predict`: zero without a colour pair; NaN for a new track).
Frame = tuple[int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any, Any, Any,
              np.ndarray, np.ndarray]
#: A filter step for the tracks of one frame: (raw, state or None per track, dt, scene-flow
#: motion) -> positions, new states.
Step = Callable[[np.ndarray, list[Any], np.ndarray, np.ndarray], tuple[np.ndarray, list[Any]]]


class _FlowRecordingTracker(_RecordingTracker):
    """Also keeps, per track id, the motion its anchor's prediction gave in the last update."""

    motion: dict[int, np.ndarray] = {}  # noqa: RUF012 - replaced, never mutated

    def _update(self, estimate, predicted):  # type: ignore[no-untyped-def]
        self.motion = dict(zip([t.id for t in self._tracks], predicted - self._anchors(),
                               strict=True))
        return super()._update(estimate, predicted)


def record_bag(bag: Path, params: EndeffParams | None = None) -> tuple[str, list[Frame]]:
    """Every track of every frame of one bag, as the tracker ran it."""
    tracker = _FlowRecordingTracker(params or EndeffParams())
    frames: list[Frame] = []
    stamp, last = 0, 0
    for f in tracked_frames(bag, tracker):
        states = tracker._tracks  # noqa: SLF001 - the recording needs the unpublished tracks
        # the frame's stamp, as the tracks hold it (a frame without tracks: 30 Hz on)
        stamp = (max(t.stamp_ns for t in states) if states
                 else stamp + (f.index - last) * 33_333_333)
        last = f.index
        published = {t.id for t in f.tracks}
        ids = np.array([t.id for t in states], dtype=np.int64)
        raw = np.array([t.raw for t in states], dtype=np.float64).reshape(-1, 3)
        flags = np.array([t.id in published for t in states], dtype=bool)
        shown = np.array([t.position for t in f.tracks], dtype=np.float64).reshape(-1, 3)
        fresh = np.array([t.age == 1 for t in states], dtype=bool)
        nan = np.full(3, np.nan)
        motion = np.array([nan if new else tracker.motion.get(t.id, nan)
                           for t, new in zip(states, fresh, strict=True)]).reshape(-1, 3)
        frames.append((f.index, stamp, ids, raw, flags, shown, f.gt, f.keys, f.kinds, fresh,
                       motion))
    return bag.name, frames


def one_euro_step(p: OneEuroParams) -> Step:
    """The tracker's filter as a replay step (state: raw, filtered, velocity)."""
    def step(raw: np.ndarray, states: list[Any], dt: np.ndarray,
             _: np.ndarray) -> tuple[np.ndarray, list[Any]]:
        out, vel = raw.copy(), np.zeros_like(raw)
        old = np.array([s is not None for s in states], dtype=bool)
        if old.any():
            prev = [s for s in states if s is not None]
            out[old], vel[old] = one_euro(raw[old], [s[0] for s in prev], [s[1] for s in prev],
                                          [s[2] for s in prev], dt[old], p)
        return out, [(r, o, w) for r, o, w in zip(raw, out, vel, strict=True)]
    return step


def _bound_lag(x: np.ndarray, z: np.ndarray, max_lag: float) -> np.ndarray:
    """``x`` pulled back to within ``max_lag`` of the raw position ``z`` (0: unbounded), as
    the tracker's filter bounds its lag."""
    lag = x - z
    n = np.linalg.norm(lag)
    return z + lag * (max_lag / n) if max_lag > 0 and n > max_lag else x


def kalman_step(q: float, r: float, reset: float = 0.2, max_lag: float = 0.05) -> Step:
    """Constant-velocity Kalman filter per axis: white-acceleration noise ``q`` (m²/s³),
    measurement noise ``r`` (m, standard deviation). State: raw, x, v, covariance (2x2)."""
    def step(raw: np.ndarray, states: list[Any], dt: np.ndarray,
             _: np.ndarray) -> tuple[np.ndarray, list[Any]]:
        out, new = raw.copy(), []
        for k, (z, s, h) in enumerate(zip(raw, states, dt, strict=True)):
            if s is None or np.linalg.norm(z - s[0]) > reset:
                cov = np.array([[r * r, 0.0], [0.0, 1.0]])
                new.append((z, z.copy(), np.zeros(3), cov))
                continue
            _, x, v, cov = s
            f = np.array([[1.0, h], [0.0, 1.0]])
            qm = q * np.array([[h ** 3 / 3, h ** 2 / 2], [h ** 2 / 2, h]])
            cov = f @ cov @ f.T + qm
            xp, vp = x + v * h, v
            gain = cov[:, 0] / (cov[0, 0] + r * r)
            innov = z - xp
            x, v = xp + gain[0] * innov, vp + gain[1] * innov
            cov = cov - np.outer(gain, cov[0])
            x = _bound_lag(x, z, max_lag)
            out[k] = x
            new.append((z, x, v, cov))
        return out, new
    return step


def flow_step(gain: float, reset: float = 0.2, max_lag: float = 0.05,
              then: OneEuroParams | None = None) -> Step:
    """A complementary filter: the last output moved by the scene flow's motion of the track
    (none: no motion) is the prediction, corrected toward the raw position by ``gain``;
    ``then``: a One Euro filter of that output. State: raw, output, (One Euro state)."""
    euro = one_euro_step(then) if then is not None else None

    def step(raw: np.ndarray, states: list[Any], dt: np.ndarray,
             motion: np.ndarray) -> tuple[np.ndarray, list[Any]]:
        out = raw.copy()
        for k, (z, s) in enumerate(zip(raw, states, strict=True)):
            if s is None or np.linalg.norm(z - s[0]) > reset:
                continue
            pred = s[1] + np.nan_to_num(motion[k])
            out[k] = _bound_lag(pred + gain * (z - pred), z, max_lag)
        if euro is None:
            return out, [(z, o, None) for z, o in zip(raw, out, strict=True)]
        shown, inner = euro(out, [None if s is None else s[2] for s in states], dt, motion)
        return shown, [(z, o, i) for z, o, i in zip(raw, out, inner, strict=True)]
    return step


def replay(frames: list[Frame], step: Step) -> list[np.ndarray]:
    """The positions ``step`` publishes in each frame (a track absent from the frame before
    starts again)."""
    states: dict[int, tuple[int, Any]] = {}  # track id -> (stamp, filter state)
    shown = []
    for _, stamp, ids, raw, flags, *_, fresh, motion in frames:
        last = [(stamp, None) if f else states.get(int(i), (stamp, None))
                for i, f in zip(ids, fresh, strict=True)]
        dt = np.array([(stamp - s) * 1e-9 for s, _ in last])
        out, new = step(raw, [st for _, st in last], dt, motion)
        states = {int(i): (stamp, s) for i, s in zip(ids, new, strict=True)}
        shown.append(out[flags])
    return shown


def score(frames: list[Frame], shown: list[np.ndarray]) -> dict[str, float]:
    """Recall, mean error, FPR and the tracking figures of one bag's replayed positions."""
    scorer = TrackingScorer()
    n_gt = n_est = tp = 0
    err = 0.0
    for (index, stamp, ids, _, flags, _, gt, keys, kinds, *_), pos in zip(frames, shown,
                                                                       strict=True):
        if gt is None:
            continue
        fs = score_frame(pos, gt)
        n_gt, n_est, tp, err = n_gt + fs.n_gt, n_est + fs.n_est, tp + fs.tp, err + fs.errors.sum()
        scorer.add(stamp, gt, keys, kinds, pos, ids[flags], fs.matches, frame=index)
    t = scorer.result()['all']
    return {'recall': tp / max(n_gt, 1), 'fp_rate': (n_est - tp) / max(n_est, 1),
            'error_m': err / max(tp, 1), 'jitter_m': t['jitter_m'],
            'accel_error_m': t['accel_error_m']}


#: Upper bounds (m per frame) of the truth's step for :func:`jitter_by_truth_step`'s bins.
TRUTH_STEP_BINS = (0.005, 0.02, 0.05, np.inf)
#: The variants whose jitter ``score`` splits by the truth's step: unfiltered and the default.
SPLIT_VARIANTS = ('raw', 'one_euro_default')


def jitter_by_truth_step(frames: list[Frame], shown: list[np.ndarray],
                         ) -> dict[str, tuple[int, float]]:
    """Jitter (mean |e_t - e_{t-1}|, as :class:`TrackingScorer` has it) split by how far the
    matched truth moved between the two frames: per bin of :data:`TRUTH_STEP_BINS`, the
    number of pairs and their jitter (m; NaN without pairs). Whether the jitter comes with
    still ends (the detection's noise, which a filter can take out) or with moving ones
    (where a filter that follows the motion passes it). A pair: one published id matched to
    one truth key in two consecutive recorded frames."""
    steps: list[float] = []
    jumps: list[float] = []
    prev: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
    last_index = None
    for (index, _, ids, _, flags, _, gt, keys, *_), pos in zip(frames, shown, strict=True):
        if gt is None or (last_index is not None and index != last_index + 1):
            prev = {}
        last_index = index
        if gt is None:
            continue
        pub = ids[flags]
        cur = {}
        for e, g in score_frame(pos, gt).matches:
            k = (int(pub[e]), int(keys[g]) if keys is not None else int(g))
            cur[k] = (pos[e] - gt[g], gt[g])
            if k in prev:
                steps.append(float(np.linalg.norm(gt[g] - prev[k][1])))
                jumps.append(float(np.linalg.norm(cur[k][0] - prev[k][0])))
        prev = cur
    st, ju = np.asarray(steps), np.asarray(jumps)
    out, lo = {}, 0.0
    for hi in TRUTH_STEP_BINS:
        m = (st >= lo) & (st < hi)
        name = f'{lo * 1e3:g}-{hi * 1e3:g} mm' if np.isfinite(hi) else f'{lo * 1e3:g}+ mm'
        out[name] = (int(m.sum()), float(ju[m].mean()) if m.any() else math.nan)
        lo = hi
    return out


def variants() -> dict[str, Step]:
    """The filters compared: none, the tracker's One Euro filter and its parameters moved one
    at a time, and constant-velocity Kalman filters."""
    p = EndeffParams()
    base = OneEuroParams(p.smoothing_min_cutoff, p.smoothing_beta, p.smoothing_d_cutoff,
                         p.smoothing_max_lag, p.smoothing_reset_distance)
    out: dict[str, Step] = {'one_euro_default': one_euro_step(base),
                            'raw': lambda r, s, d, m: (r.copy(), [None] * len(r))}
    for name, change in (('beta3', {'beta': 3.0}), ('beta20', {'beta': 20.0}),
                         ('min_cutoff1', {'min_cutoff': 1.0}), ('d_cutoff2', {'d_cutoff': 2.0}),
                         ('max_lag3cm', {'max_lag': 0.03})):
        out[f'one_euro_{name}'] = one_euro_step(base._replace(**change))
    for q, r in ((5.0, 0.02), (20.0, 0.01), (80.0, 0.01)):
        out[f'kalman_q{q:g}_r{r:g}'] = kalman_step(q, r, base.reset_distance, base.max_lag)
    for gain in (0.3, 0.5, 0.7):
        out[f'flow_gain{gain:g}'] = flow_step(gain, base.reset_distance, base.max_lag)
        out[f'flow_gain{gain:g}_one_euro'] = flow_step(gain, base.reset_distance, base.max_lag,
                                                       base)
    return out


def _mean(rows: list[dict[str, float]]) -> dict[str, float]:
    return {k: float(np.nanmean([r[k] for r in rows])) for k in rows[0]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    sub = parser.add_subparsers(dest='command', required=True)
    c = sub.add_parser('collect')
    c.add_argument('bags', nargs='+')
    c.add_argument('--out', required=True)
    c.add_argument('--jobs', type=int, default=1)
    c.add_argument('--params', help='parameter YAML (default: the defaults)')
    s = sub.add_parser('score')
    s.add_argument('file')
    s.add_argument('--json')
    args = parser.parse_args(argv)
    if args.command == 'collect':
        from endeff_ros.bag.reader import find_bags

        bags = sorted(find_bags(args.bags))
        params = load_params_option(args.params, 'smoothing_replay')
        runs = run_per_bag(record_bag, bags, params, args.jobs)
        with open(args.out, 'wb') as fh:
            pickle.dump(runs, fh)
        print(f'{len(runs)} bags recorded in {args.out}')
        return 0
    with open(args.file, 'rb') as fh:
        runs = pickle.load(fh)  # noqa: S301 - a file this tool wrote
    steps = variants()
    worst = max(float(np.max(np.abs(s - f[5]), initial=0.0))
                for _, frames in runs
                for s, f in zip(replay(frames, steps['one_euro_default']), frames,
                                strict=True))
    print(f'replay of the default filter: largest difference to the published {worst:.2e} m')
    report = {}
    splits: dict[str, dict[str, tuple[int, float]]] = {}
    for name, step in steps.items():
        shown = [replay(frames, step) for _, frames in runs]
        report[name] = _mean([score(frames, s) for (_, frames), s in zip(runs, shown)])
        r = report[name]
        print(f'{name:22s} recall {r["recall"]:.4f} fpr {r["fp_rate"]:.4f} '
              f'err {r["error_m"] * 100:.2f} cm jitter {r["jitter_m"] * 1e3:.1f} mm '
              f'acc {r["accel_error_m"] * 1e3:.1f} mm', flush=True)
        if name in SPLIT_VARIANTS:
            pairs: dict[str, list[tuple[int, float]]] = {}
            for (_, frames), s in zip(runs, shown):
                for b, v in jitter_by_truth_step(frames, s).items():
                    pairs.setdefault(b, []).append(v)
            splits[name] = report[name]['jitter_by_truth_step'] = {
                b: (sum(n for n, _ in v),
                    sum(n * j for n, j in v if n) / max(sum(n for n, _ in v), 1))
                for b, v in pairs.items()}
    for name, split in splits.items():
        print(f"{name:22s} jitter by the truth's step a frame: " + ', '.join(
            f'{b} {j * 1e3:.1f} mm ({n} pairs)' for b, (n, j) in split.items()))
    if args.json:
        print_json(report, args.json)
    return 0


if __name__ == '__main__':
    sys.exit(main())
