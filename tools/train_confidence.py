"""Fit the confidence model (:mod:`endeff_ros.core.confidence`) on benchmark bags.

Two steps, so the tracker's run (minutes) and the fit (seconds) can be repeated apart:

    python -m tools.train_confidence collect BAG_OR_DIR [...] --out DIR [--jobs 2]
    python -m tools.train_confidence fit DIR [...] [--model OUT.json] [--json REPORT]
                                         [--holdout] [--balance]
    python -m tools.train_confidence score DIR [...] [--model M.json] [--json REPORT]

``collect`` runs the tracker with the paper's confidence (``scored_confidence: false``) and
every end published (``min_confidence: 0``) over each bag and writes one ``.npz`` per bag:
per published end of a frame with ground truth its evidence (:func:`end_features`), whether
the frame's matching (0.15 m, as ``endeff eval``) made it right, the frame, the paper's
confidence; per frame its ground-truth count. ``fit`` cuts each feature at the quantiles of
the ends (at most :data:`BINS` intervals), fits the additive logistic model by Newton's method
with penalties on the differences of neighbouring intervals' weights (:data:`PENALTY`) and on
the weights (:data:`RIDGE`), and writes the model (default the committed
``endeff_ros/core/confidence_model.json``); ``--holdout`` instead fits on the bags of half the
clips and reports on the others, both ways. ``score`` reports a model on other bags. Reports:
average precision and calibration error of the model and of the paper's confidence, and per
``min_confidence`` the recall and FPR (means over bags, overall and per group of
:data:`GROUPS`) with the frame matching held fixed.

The committed model comes from the ``dev`` bags only (docs/design.md, "Confidence"): the mocap
suite's dev split (``endeff synth --suite mocap --only 'dev__*'``), its still and slow dev bags,
the rooms' dev pairs, and the paper suite's generic entities drawn with seeds 1-5 (``endeff
synth --only generic --seed N``), so that it learns what an end is on chairs, robot arms and
stars too.
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from endeff_ros.attributes import custom_data, parse_attributes
from endeff_ros.bag.reader import BagReader
from endeff_ros.core.confidence import FEATURES, MODEL_FILE, NO_FLOOR, ConfidenceModel
from endeff_ros.core.errors import InputError
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.tracker import Tracker
from endeff_ros.ranking import average_precision, calibration_bins, calibration_error
from endeff_ros.scoring import score_frame
from tools import additive_fit

BINS = 8
"""Intervals per continuous feature (cut at quantiles of the training ends)."""
PENALTY = 30.0
"""Penalty on the squared differences of neighbouring intervals' weights (in units of the
log-likelihood of one end): each feature's effect is smooth unless many ends say otherwise."""
RIDGE = 1.0
"""Penalty on the squared weights (keeps the fit defined where a feature is constant)."""
BINARY = ('detected', 'head', 'hand', 'foot')
"""Features that are 0 or 1: one cut at 0.5."""


def collect_bag(bag: Path, params: EndeffParams | None = None, *, out: Path) -> str:
    """Run the tracker over ``bag`` and write its ends' evidence to ``out/<bag>.npz``."""
    params = replace(params or EndeffParams(), scored_confidence=False, min_confidence=0.0)
    tracker = Tracker(params)
    feats, right, frame, paper, n_gt = [], [], [], [], []
    with BagReader(bag) as reader:
        attributes, _ = parse_attributes(custom_data(reader.reader), str(bag))
        for frm, gt in reader.frames():
            try:
                tracks = tracker.update(frm).tracks
            except InputError:
                continue
            if gt is None:
                continue
            positions = np.array([t.position for t in tracks], dtype=np.float64).reshape(-1, 3)
            score = score_frame(positions, np.asarray(gt, dtype=np.float64)[:, :3])
            ok = np.zeros(len(tracks), dtype=bool)
            ok[score.matches[:, 0]] = True
            feats.append(tracker.features.reshape(len(tracks), len(FEATURES)))
            right.append(ok)
            frame.append(np.full(len(tracks), len(n_gt)))
            paper.append([t.confidence for t in tracks])
            n_gt.append(score.n_gt)
    name = additive_fit.collected_name(bag)
    np.savez_compressed(
        out / f'{name}.npz', features=np.concatenate(feats or [np.zeros((0, len(FEATURES)))]),
        right=np.concatenate(right or [np.zeros(0, bool)]),
        frame=np.concatenate(frame or [np.zeros(0, int)]),
        paper=np.concatenate([np.asarray(p, dtype=np.float64) for p in paper] or [np.zeros(0)]),
        n_gt=np.asarray(n_gt, dtype=np.int64), names=np.asarray(FEATURES),
        attributes=json.dumps(attributes))
    return name


def load(dirs: list[Path]) -> dict[str, Any]:
    """Every collected bag in ``dirs``: stacked ends, their bag index, and per bag its
    ground-truth count and attributes."""
    files = additive_fit.collected_files(dirs)
    parts = [np.load(f) for f in files]
    for f, p in zip(files, parts, strict=True):
        if tuple(p['names']) != FEATURES:
            msg = f'{f}: collected with other features; collect again'
            raise SystemExit(msg)
    return {'features': np.concatenate([p['features'] for p in parts]),
            'right': np.concatenate([p['right'] for p in parts]),
            'paper': np.concatenate([p['paper'] for p in parts]),
            'bag': np.concatenate([np.full(len(p['right']), i) for i, p in enumerate(parts)]),
            'frame': np.concatenate([p['frame'] for p in parts]),
            'frames': np.array([len(p['n_gt']) for p in parts]),
            'n_gt': np.array([int(p['n_gt'].sum()) for p in parts]),
            'names': [f.stem for f in files],
            'attributes': [json.loads(str(p['attributes'])) for p in parts]}


def subset(data: dict[str, Any], bags: np.ndarray) -> dict[str, Any]:
    """The collected ``data`` of the bags where ``bags`` (per bag, bool) holds, renumbered."""
    index = np.flatnonzero(bags)
    ends = np.isin(data['bag'], index)
    renumber = np.full(len(bags), -1)
    renumber[index] = np.arange(len(index))
    out = {k: data[k][ends] for k in ('features', 'right', 'paper', 'frame')}
    out['bag'] = renumber[data['bag'][ends]]
    for k in ('frames', 'n_gt'):
        out[k] = data[k][index]
    for k in ('names', 'attributes'):
        out[k] = [data[k][i] for i in index]
    return out


def bag_weights(data: dict[str, Any]) -> np.ndarray:
    """Per end the weight that gives every bag the same total (the mean end weighs 1)."""
    counts = np.bincount(data['bag'], minlength=len(data['names']))
    w = 1.0 / counts[data['bag']]
    return w * len(w) / w.sum()


def fit(features: np.ndarray, right: np.ndarray, *, penalty: float = PENALTY,
        weight: np.ndarray | None = None) -> ConfidenceModel:
    """The confidence model fitted to ``features`` (:func:`tools.additive_fit.fit`)."""
    return additive_fit.fit(ConfidenceModel, features, right, binary=BINARY, bins=BINS,
                            penalty=penalty, ridge=RIDGE, sentinels={'height': NO_FLOOR},
                            weight=weight)


def summary(data: dict[str, Any], confidence: np.ndarray) -> dict[str, float]:
    """AP (mean over bags) and calibration error (pooled) of ``confidence`` on ``data``."""
    aps = [average_precision(confidence[data['bag'] == i], data['right'][data['bag'] == i], n)
           for i, n in enumerate(data['n_gt']) if n > 0]
    return {'average_precision': float(np.mean(aps)),
            'calibration_error': calibration_error(calibration_bins(confidence, data['right']))}


def bag_scores(data: dict[str, Any], keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per bag its recall and FPR (means over its frames, as ``endeff eval``) with only the
    ``keep`` ends published, the frame matching held fixed (an end removed frees no label)."""
    recall, fpr = np.full(len(data['names']), np.nan), np.zeros(len(data['names']))
    for i, n in enumerate(data['frames']):
        of = data['bag'] == i
        frame, right, kept = data['frame'][of], data['right'][of], keep[of]
        shown = np.bincount(frame[kept], minlength=n)
        wrong = np.bincount(frame[kept & ~right], minlength=n)
        fpr[i] = np.mean(np.where(shown > 0, wrong / np.maximum(shown, 1), 0.0)) if n else 0.0
        if data['n_gt'][i]:
            recall[i] = (right & kept).sum() / data['n_gt'][i]
    return recall, fpr


GROUPS = ('motion', 'room', 'people', 'child', 'sensor')
"""Attributes whose groups the fit report shows (people first: a threshold that costs a group
its recall is seen there)."""


def operating_points(data: dict[str, Any], confidence: np.ndarray,
                     thresholds: tuple[float, ...] = (0.0, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3),
                     ) -> list[dict[str, Any]]:
    """Per ``min_confidence``: recall and FPR (means over the bags, and per group of
    :data:`GROUPS`), the frame matching held fixed."""
    out = []
    for t in thresholds:
        recall, fpr = bag_scores(data, confidence >= t)
        row: dict[str, Any] = {'min_confidence': t, 'recall': float(np.nanmean(recall)),
                               'fpr': float(np.mean(fpr))}
        for key in GROUPS:
            values = [str(a.get(key)) for a in data['attributes']]
            for v in sorted(set(values)):
                sel = np.array([x == v for x in values])
                row[f'{key}={v}'] = (round(float(np.nanmean(recall[sel])), 3),
                                     round(float(np.mean(fpr[sel])), 3))
        out.append(row)
    return out


def report(data: dict[str, Any], confidence: np.ndarray) -> dict[str, Any]:
    """The model's and the paper's AP and calibration, and the operating points, on ``data``."""
    return {'bags': len(data['names']), 'ends': len(data['right']),
            'right': float(data['right'].mean()), 'model': summary(data, confidence),
            'paper': summary(data, data['paper']),
            'operating_points': operating_points(data, confidence)}


def main(argv: list[str] | None = None) -> int:
    parser, f = additive_fit.steps_parser(__doc__, MODEL_FILE, 'model')
    f.add_argument('--penalty', type=float, default=PENALTY)
    f.add_argument('--balance', action='store_true',
                   help='every bag weighs the same in the fit (default: every end)')
    args = parser.parse_args(argv)
    if args.step == 'collect':
        return additive_fit.collect(collect_bag, args)
    data = load([Path(d) for d in args.dirs])
    if args.step == 'score':
        additive_fit.print_report(report(data, ConfidenceModel.load(args.model)(
            data['features'])), args.json)
        return 0
    weight = bag_weights(data) if args.balance else None
    if args.holdout:
        fold = np.array([additive_fit.holdout_fold(n) for n in data['names']])
        folds = []
        for k in (0, 1):
            train, held = subset(data, fold != k), subset(data, fold == k)
            m = fit(train['features'], train['right'], penalty=args.penalty,
                    weight=None if weight is None else weight[np.isin(data['bag'],
                                                                      np.flatnonzero(fold != k))])
            folds.append({'held_out_fold': k, **report(held, m(held['features']))})
        additive_fit.print_report({'folds': folds}, args.json)
        return 0
    model = fit(data['features'], data['right'], penalty=args.penalty, weight=weight)
    additive_fit.write_model(model, args.model)
    additive_fit.print_report(report(data, model(data['features'])), args.json)
    return 0


if __name__ == '__main__':
    sys.exit(main())
