"""Fit the candidate scorer (:mod:`endeff_ros.core.candidates`) on benchmark bags.

Two steps, so the estimator's run (minutes) and the fit (seconds) can be repeated apart:

    python -m tools.train_candidates collect BAG_OR_DIR [...] --out DIR [--jobs 2]
    python -m tools.train_candidates fit DIR [...] [--model OUT.json] [--json REPORT]
                                         [--holdout]
    python -m tools.train_candidates score DIR [...] [--model M.json] [--json REPORT]

``collect`` runs the single-frame estimator as ``endeff eval`` does (its own static
background per bag) with candidates over-generated (the default ``candidate_floor``) and the
thresholds deciding, and writes one ``.npz`` per bag: per
over-generated candidate of a frame with ground truth its evidence
(:func:`~endeff_ros.core.candidates.candidate_features`), its position, whether the frame's
matching of *all* candidates (0.15 m, as ``endeff eval``) made it right, the thresholds'
verdict; per frame its ground truth. ``fit`` fits the additive logistic model
(:func:`tools.additive_fit.fit`) and writes it (default the committed
``endeff_ros/core/candidate_model.json``); ``--holdout`` fits on the bags of half the clips
and reports on the others, both ways. Reports: per pair of ``drop_candidate_score`` and
``min_candidate_score`` (:data:`RULES`) the recall and FPR (means over the bags of people and
over the others', each frame matched again over the kept candidates, as ``endeff eval``
would), against the thresholds' own.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from endeff_ros.attributes import custom_data, parse_attributes
from endeff_ros.bag.reader import BagReader
from endeff_ros.core.candidates import BINARY, FEATURES, MODEL_FILE, CandidateModel
from endeff_ros.core.confidence import NO_FLOOR
from endeff_ros.core.errors import InputError
from endeff_ros.core.params import EndeffParams
from endeff_ros.scoring import score_frame
from tools import additive_fit

BINS = 8
PENALTY = 30.0
RIDGE = 1.0
RULES = tuple((drop, least) for drop in (0.1, 0.15, 0.2) for least in (0.3, 0.4, 0.5)) + (
    (0.4, 0.4),)
"""(``drop_candidate_score``, ``min_candidate_score``) pairs the reports show; (0.4, 0.4):
the score alone."""


def collect_bag(bag: Path, params: EndeffParams | None = None, *, out: Path) -> str:
    """Run the single-frame estimator over ``bag``; write its candidates' evidence to
    ``out/<bag>.npz``."""
    from dataclasses import replace

    from endeff_ros.evaluate import _background_estimate

    params = replace(params or EndeffParams(), candidate_scorer=False)  # the default floor
    estimate = _background_estimate()
    feats, right, kept, frame, pos, gts, gt_frame = [], [], [], [], [], [], []
    n = 0
    with BagReader(bag) as reader:
        attributes, _ = parse_attributes(custom_data(reader.reader), str(bag))
        for frm, gt in reader.frames():
            try:
                est = estimate(frm, params)
            except InputError:
                continue
            if gt is None:
                continue
            gt = np.asarray(gt, dtype=np.float64)[:, :3]
            scored = est.scored
            m = 0 if scored is None else len(scored.kept)
            if m:
                ok = np.zeros(m, dtype=bool)
                ok[score_frame(scored.positions, gt).matches[:, 0]] = True
                feats.append(scored.features)
                right.append(ok)
                kept.append(scored.kept)
                pos.append(scored.positions)
                frame.append(np.full(m, n))
            gts.append(gt)
            gt_frame.append(np.full(len(gt), n))
            n += 1
    name = additive_fit.collected_name(bag)

    def cat(parts: list[np.ndarray], shape: tuple[int, ...], dtype: Any = np.float64) -> Any:
        return np.concatenate(parts) if parts else np.zeros(shape, dtype)

    np.savez_compressed(
        out / f'{name}.npz', features=cat(feats, (0, len(FEATURES))),
        right=cat(right, (0,), bool), kept=cat(kept, (0,), bool), frame=cat(frame, (0,), int),
        positions=cat(pos, (0, 3)), gt=cat(gts, (0, 3)), gt_frame=cat(gt_frame, (0,), int),
        frames=n, names=np.asarray(FEATURES), attributes=json.dumps(attributes))
    return name


def load(dirs: list[Path]) -> list[dict[str, Any]]:
    """Every collected bag in ``dirs``, one dict each."""
    out = []
    for f in additive_fit.collected_files(dirs):
        p = np.load(f)
        if tuple(p['names']) != FEATURES:
            msg = f'{f}: collected with other features; collect again'
            raise SystemExit(msg)
        d = {k: p[k] for k in ('features', 'right', 'kept', 'frame', 'positions', 'gt',
                               'gt_frame')}
        d.update(name=f.stem, frames=int(p['frames']),
                 attributes=json.loads(str(p['attributes'])))
        out.append(d)
    return out


def fit(bags: list[dict[str, Any]]) -> CandidateModel:
    """The candidate model fitted to the candidates of ``bags``."""
    features = np.concatenate([b['features'] for b in bags])
    right = np.concatenate([b['right'] for b in bags])
    return additive_fit.fit(CandidateModel, features, right, bins=BINS, penalty=PENALTY,
                            ridge=RIDGE, binary=BINARY, sentinels={'height': NO_FLOOR})


def bag_score(bag: dict[str, Any], keep: np.ndarray) -> tuple[float, float]:
    """The bag's recall and FPR (means over its frames, as ``endeff eval``) with only the
    ``keep`` candidates, each frame matched again."""
    recalls, fprs = [], []
    for t in range(bag['frames']):
        gt = bag['gt'][bag['gt_frame'] == t]
        est = bag['positions'][(bag['frame'] == t) & keep]
        s = score_frame(est, gt)
        if len(gt):
            recalls.append(s.tp / len(gt))
        fprs.append((len(est) - s.tp) / len(est) if len(est) else 0.0)
    return (float(np.mean(recalls)) if recalls else float('nan'),
            float(np.mean(fprs)) if fprs else 0.0)


def operating_points(bags: list[dict[str, Any]], model: CandidateModel) -> list[dict[str, Any]]:
    """The thresholds' recall and FPR, then per pair of :data:`RULES` the model's (means over
    the bags of people, and over the other entities' bags: the paper suite's)."""
    scores = [model(b['features']) for b in bags]
    people = np.array([b['attributes'].get('room') is not None for b in bags])
    rows = []
    for label, keeps in [('thresholds', [b['kept'] for b in bags])] + [
            (f'drop {drop} / min {least}',
             [np.where(b['kept'], s >= drop, s >= least) for b, s in zip(bags, scores,
                                                                          strict=True)])
            for drop, least in RULES]:
        per = np.array([bag_score(b, k) for b, k in zip(bags, keeps, strict=True)])
        row: dict[str, Any] = {'keep': label}
        for name, sel in (('people', people), ('other entities', ~people)):
            if sel.any():
                row[name] = (round(float(np.nanmean(per[sel, 0])), 3),
                             round(float(np.mean(per[sel, 1])), 3))
        for v in ('empty', 'wall', 'furnished'):
            sel = np.array([b['attributes'].get('room') == v for b in bags])
            if sel.any():
                row[f'room={v}'] = (round(float(np.nanmean(per[sel, 0])), 3),
                                    round(float(np.mean(per[sel, 1])), 3))
        rows.append(row)
    return rows


def report(bags: list[dict[str, Any]], model: CandidateModel) -> dict[str, Any]:
    right = np.concatenate([b['right'] for b in bags])
    kept = np.concatenate([b['kept'] for b in bags])
    return {'bags': len(bags), 'candidates': int(len(right)), 'right': float(right.mean()),
            'kept_by_thresholds': float(kept.mean()),
            'right_among_dropped': float(right[~kept].mean()) if (~kept).any() else None,
            'operating_points': operating_points(bags, model)}


def main(argv: list[str] | None = None) -> int:
    parser, _ = additive_fit.steps_parser(__doc__, MODEL_FILE, 'candidate model')
    args = parser.parse_args(argv)
    if args.step == 'collect':
        return additive_fit.collect(collect_bag, args)
    bags = load([Path(d) for d in args.dirs])
    if args.step == 'score':
        additive_fit.print_report(report(bags, CandidateModel.load(args.model)), args.json)
        return 0
    if args.holdout:
        additive_fit.print_report(additive_fit.holdout_report(bags, fit, report), args.json)
        return 0
    model = fit(bags)
    additive_fit.write_model(model, args.model)
    additive_fit.print_report(report(bags, model), args.json)
    return 0


if __name__ == '__main__':
    sys.exit(main())
