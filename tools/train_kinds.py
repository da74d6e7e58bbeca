"""Fit the person and head models of the published kinds (``core/kind_model.json``).

Two steps, so the tracker's run (minutes) and the fit (seconds) can be repeated apart:

    python -m tools.train_kinds collect BAG_OR_DIR [...] --out DIR [--jobs 2]
    python -m tools.train_kinds fit DIR [...] [--model OUT.json] [--json REPORT] [--holdout]
    python -m tools.train_kinds score DIR [...] [--model M.json] [--json REPORT]

``collect`` runs the tracker with the rules' kinds (``scored_kinds: false``, so that the
collection does not depend on an earlier model) over each bag and writes one ``.npz`` per bag:
per published end of every frame its track id and age, its :class:`KindEvidence`, and the kind
of the ground-truth end-effector the frame's matching (0.15 m, as ``endeff eval``) gives it
(-1: none; 0 in a bag without people). ``fit`` fits the person model on one row per entity and
frame (a person when one of its ends matched a person's end-effector) and the head model on
the matched ends of people that are not by the floor (a head or not), and writes them (default
the committed ``endeff_ros/core/kind_model.json``); ``--holdout`` instead fits on the bags of
half the clips and reports on the others, both ways. The report replays the kinds frame by
frame, vote history included (:meth:`KindLabeller.label_evidence`), with the models and with
the rules: the share of matched ends whose kind is right (overall, per kind, as ``endeff
eval``'s confusion matrix), the share of ends of bags without people that are not 0, and for
the static background's entities of the start (``background_person_s``) how many people in view
at the start were not yet taken for one, and other entities were, within 6, 15 and 30 frames.

The committed models come from the ``dev`` bags only (docs/design.md, "Which part an end
is"): ``collect data/mocap_dev data/rooms data/generic_seed{1..5}/mcap``, the mocap suite's dev
split, the rooms' dev pairs and the paper suite's generic entities drawn with seeds 1-5
(chairs, robot arms, stars, two people).
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from endeff_ros.attributes import custom_data, parse_attributes
from endeff_ros.bag.reader import BagReader, bag_name
from endeff_ros.core.errors import InputError
from endeff_ros.core.kinds import (
    HEAD_FEATURES,
    KIND_MODEL_FILE,
    KIND_NAMES,
    NO_FLOOR,
    PERSON_FEATURES,
    HeadModel,
    KindEvidence,
    KindLabeller,
    KindModels,
    PersonModel,
)
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.tracker import Tracker
from endeff_ros.evaluate import gt_ids, is_person_sequence
from endeff_ros.scoring import kinds_of_ids, score_frame
from tools import additive_fit

BINS = 8
"""Intervals per continuous feature (cut at quantiles of the training rows)."""
PENALTY = 30.0
"""Penalty on the squared differences of neighbouring intervals' weights."""
RIDGE = 1.0
"""Penalty on the squared weights."""
GENERIC_SHARE = 0.5
"""The share of the person model's weight on the bags without people (chairs, robot arms,
stars): a few bags of three shapes against two hundred of people, which weighed by their rows
alone made every chair and star a person."""
START_FRAMES = 6
"""A person in view within this many first frames (the background's learning, 0.2 s at 30
Hz) is one of the start."""
START_WINDOWS = (6, 15, 30)
"""Frames from the start within which :func:`first_taken` counts an entity as taken for a
person (``background_person_s`` 0.8 s after 0.2 s of learning: 30 at 30 Hz)."""
NEVER = 1 << 30
PERSON_BINARY = ('on_floor', 'cut', 'cut_top', 'rules')
HEAD_BINARY = ('cut',)
_FIELDS = ('entities', 'low', 'person', 'head', 'rules_person', 'rules_head')
_TRUTH = {name: code for code, name in enumerate(KIND_NAMES)}


def collect_bag(bag: Path, params: EndeffParams | None = None, *, out: Path) -> str:
    """Run the tracker over ``bag`` and write its ends' kind evidence to ``out/<bag>.npz``."""
    params = replace(params or EndeffParams(), scored_kinds=False, min_confidence=0.0)
    tracker = Tracker(params)
    rows: dict[str, list[Any]] = {k: [] for k in (*_FIELDS, 'id', 'age', 'frame', 'truth')}
    with BagReader(bag) as reader:
        attributes, _ = parse_attributes(custom_data(reader.reader), str(bag))
        person = is_person_sequence(bag_name(bag), attributes)
        ids = gt_ids(reader)
        for k, (frm, gt) in enumerate(reader.frames()):
            try:
                tracks = tracker.update(frm).tracks
            except InputError:
                continue
            ev = tracker.kinds.evidence
            if not tracks or ev is None:
                continue
            truth = np.full(len(tracks), -1)
            if gt is not None and frm.stamp_ns in ids:
                positions = np.array([t.position for t in tracks], dtype=np.float64)
                score = score_frame(positions, np.asarray(gt, dtype=np.float64)[:, :3])
                names = kinds_of_ids(ids[frm.stamp_ns], person=person)
                truth[score.matches[:, 0]] = [_TRUTH[str(names[j])] for j in score.matches[:, 1]]
            for name in _FIELDS:
                rows[name].append(getattr(ev, name))
            rows['id'].append([t.id for t in tracks])
            rows['age'].append([t.age for t in tracks])
            rows['frame'].append(np.full(len(tracks), k))
            rows['truth'].append(truth)
    name = additive_fit.collected_name(bag)
    empty = {'person': np.zeros((0, len(PERSON_FEATURES))),
             'head': np.zeros((0, len(HEAD_FEATURES)))}
    np.savez_compressed(out / f'{name}.npz', person_bag=person, attributes=json.dumps(attributes),
                        person_names=np.asarray(PERSON_FEATURES),
                        head_names=np.asarray(HEAD_FEATURES),
                        **{k: np.concatenate(v) if v else empty.get(k, np.zeros(0))
                           for k, v in rows.items()})
    return name


def load(dirs: list[Path]) -> list[dict[str, Any]]:
    """Every collected bag in ``dirs``, with its name."""
    bags = []
    for f in additive_fit.collected_files(dirs):
        with np.load(f) as z:
            if (tuple(z['person_names']) != PERSON_FEATURES
                    or tuple(z['head_names']) != HEAD_FEATURES):
                msg = f'{f}: collected with other features; collect again'
                raise SystemExit(msg)
            bags.append({'name': f.stem, **{k: z[k] for k in z.files}})
    return bags


def training_rows(bags: list[dict[str, Any]]) -> tuple[np.ndarray, ...]:
    """The person model's rows (one per entity and frame: features, person or not, weight)
    and the head model's (matched ends of people not by the floor: features, head or not).
    The bags without people weigh as much in the person model as the bags with people
    (:data:`GENERIC_SHARE`)."""
    px, py, pw, hx, hy = [], [], [], [], []
    for b in bags:
        key = b['frame'] * 1000 + b['entities']
        known = b['entities'] >= 0
        _, first = np.unique(key[known], return_index=True)
        rows = np.flatnonzero(known)[first]
        people = bool(b['person_bag'])
        matched = (np.isin(key, np.unique(key[known & (b['truth'] >= 1)])) if people
                   else np.zeros(len(key), dtype=bool))
        px.append(b['person'][rows])
        py.append(matched[rows])
        pw.append(np.full(len(rows), float(people)))
        heads = known & (b['truth'] >= 1) & ~b['low']
        hx.append(b['head'][heads])
        hy.append(b['truth'][heads] == _TRUTH['head'])
    people = np.concatenate(pw).astype(bool)
    weight = np.where(people, (1 - GENERIC_SHARE) / max(people.sum(), 1),
                      GENERIC_SHARE / max((~people).sum(), 1)) * len(people)
    if people.all() or not people.any():
        weight = np.ones(len(people))
    return (np.concatenate(px), np.concatenate(py), weight, np.concatenate(hx),
            np.concatenate(hy))


def fit(bags: list[dict[str, Any]], *, penalty: float = PENALTY) -> KindModels:
    """The person and head models fitted to ``bags``."""
    px, py, pw, hx, hy = training_rows(bags)
    common = {'bins': BINS, 'penalty': penalty, 'ridge': RIDGE}
    sentinels = {'bottom': NO_FLOOR, 'top': NO_FLOOR}
    return KindModels(
        additive_fit.fit(PersonModel, px, py, binary=PERSON_BINARY, sentinels=sentinels,
                         weight=pw, **common),
        additive_fit.fit(HeadModel, hx, hy, binary=HEAD_BINARY, **common))


def replay(bag: dict[str, Any], models: KindModels | None) -> np.ndarray:
    """Per collected end of ``bag`` its published kind, frame by frame with the vote history
    (``models`` None: the rules)."""
    labeller = KindLabeller(models=models)
    out = np.zeros(len(bag['frame']), dtype=np.intp)
    starts = np.flatnonzero(np.r_[True, np.diff(bag['frame']) != 0])
    for a, b in zip(starts, np.r_[starts[1:], len(bag['frame'])], strict=True):
        ev = KindEvidence(*(bag[k][a:b] for k in _FIELDS))
        out[a:b] = labeller.label_evidence(bag['id'][a:b].tolist(), bag['age'][a:b].tolist(), ev)
    return out


def first_taken(bag: dict[str, Any], kinds: np.ndarray) -> tuple[list[int], list[int]]:
    """For the static background's entities of the start (``background_person_s``): the
    frame in which an end of the person in view at the start (an entity holding a matched end
    in the bag's first :data:`START_FRAMES` frames) was first taken for a person's (kind not
    0), and the same for each entity of the bag's first frame none of whose tracks ever
    matches a person's end-effector (furniture, mostly); :data:`NEVER` when never."""
    frame, entity, truth, ids = bag['frame'], bag['entities'], bag['truth'], bag['id']
    people: list[int] = []
    if (truth[frame < START_FRAMES] >= 1).any():
        matched = np.zeros(len(frame), dtype=bool)
        for f in np.unique(frame):
            at = frame == f
            matched |= at & np.isin(entity, entity[at & (truth >= 1) & (entity >= 0)])
        taken = frame[matched & (kinds != 0)]
        people.append(int(taken.min()) if taken.size else NEVER)
    first = frame == frame.min() if len(frame) else np.zeros(0, dtype=bool)
    person_ids = ids[truth >= 1]
    others = []
    for e in np.unique(entity[first & (entity >= 0)]):
        tracks = ids[first & (entity == e)]
        if np.isin(tracks, person_ids).any():
            continue
        taken = frame[np.isin(ids, tracks) & (kinds != 0)]
        others.append(int(taken.min()) if taken.size else NEVER)
    return people, others


def accuracy(bags: list[dict[str, Any]], models: KindModels | None) -> dict[str, Any]:
    """Replayed kinds against the truth: the confusion of matched ends (rows head, hand,
    foot; columns other, head, hand, foot), the right share overall and per kind, the share
    of ends in bags without people that are not 0, and of the bags with people, per window of
    :data:`START_WINDOWS` frames: the people in view at the start not taken for one within it
    and the other entities of the start that were (:func:`first_taken`)."""
    counts = np.zeros((3, 4), dtype=np.int64)
    other, total = 0, 0
    people: list[int] = []
    others: list[int] = []
    for b in bags:
        kinds = replay(b, models)
        if bool(b['person_bag']):
            m = b['truth'] >= 1
            np.add.at(counts, (b['truth'][m] - 1, kinds[m]), 1)
            p, o = first_taken(b, kinds)
            people += p
            others += o
        else:
            other += int(np.count_nonzero(kinds != 0))
            total += len(kinds)
    right = np.trace(counts[:, 1:])
    first_p, first_o = np.array(people), np.array(others)
    return {'accuracy': round(float(right / max(counts.sum(), 1)), 4),
            **{KIND_NAMES[k + 1]: round(float(counts[k, k + 1] / max(counts[k].sum(), 1)), 4)
               for k in range(3)},
            'confusion': counts.tolist(), 'matched': int(counts.sum()),
            'no_people_not_other': round(other / max(total, 1), 4),
            'start': {'people': len(people), 'other_entities': len(others),
                      **{f'within_{w}': {'people_not_taken': int(np.sum(first_p >= w)),
                                         'others_taken': int(np.sum(first_o < w))}
                         for w in START_WINDOWS}}}


def report(bags: list[dict[str, Any]], models: KindModels) -> dict[str, Any]:
    """The models' and the rules' replayed kinds on ``bags``."""
    return {'bags': len(bags), 'models': accuracy(bags, models), 'rules': accuracy(bags, None)}


def main(argv: list[str] | None = None) -> int:
    parser, f = additive_fit.steps_parser(__doc__, KIND_MODEL_FILE, 'person and head models')
    f.add_argument('--penalty', type=float, default=PENALTY)
    args = parser.parse_args(argv)
    if args.step == 'collect':
        return additive_fit.collect(collect_bag, args)
    bags = load([Path(d) for d in args.dirs])
    if args.step == 'score':
        additive_fit.print_report(report(bags, KindModels.load(args.model)), args.json)
        return 0
    if args.holdout:
        additive_fit.print_report(additive_fit.holdout_report(
            bags, lambda train: fit(train, penalty=args.penalty), report), args.json)
        return 0
    models = fit(bags, penalty=args.penalty)
    additive_fit.write_model(models, args.model)
    additive_fit.print_report(report(bags, models), args.json)
    return 0


if __name__ == '__main__':
    sys.exit(main())
