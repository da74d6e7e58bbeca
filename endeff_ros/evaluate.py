"""``endeff eval``: score the temporal and the single-frame estimator on benchmark bags.

Every bag in the benchmark-bag form (``docs/benchmark-bags.md``), written by anyone,
is scored: frames are read and synchronised by :mod:`endeff_ros.bag.reader`, each frame goes to
the temporal :class:`~endeff_ros.core.tracker.Tracker` and to the single-frame
:func:`~endeff_ros.core.single_frame.estimate_frame` in the same run, and both are scored with
:mod:`endeff_ros.scoring` (Section 6.1, Eqs. 10-12).

Output: a table on stdout, optionally the JSON report (``--json``, the spec's form plus extra
keys ``per_frame``, ``groups``, ``kinds``, ``failed``...) and plots (``--plots``). Progress and
the topic choice per bag go to stderr. Exit status 1 if any bag failed, 2 if an input path
or an output cannot be used (before any work), else 0 (:mod:`endeff_ros.cli_common`).

Groups: the paper suite's named groups (``no_occlusion``, ``occlusion``, ``generic``), and one
group per value of every attribute that bags record in their metadata
(:mod:`endeff_ros.attributes`, e.g. ``view=side``, ``distance_m=2-3.5``). Kinds: for sequences
of people (attribute ``people`` > 0, or a person sequence of the paper suite) the ground-truth
ids are heads, hands and feet (id % 5, the contract's numbering), scored per kind
(:meth:`~endeff_ros.scoring.SequenceScorer.kind_result`); other entities are kind ``other``.

No ROS import: this runs without rclpy.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from endeff_ros.attributes import (
    attribute_groups,
    custom_data,
    group_sections,
    parse_attributes,
)
from endeff_ros.bag import progress as prog
from endeff_ros.bag.errors import BagError
from endeff_ros.bag.outputs import check_output_option
from endeff_ros.bag.reader import (
    BagReader,
    ReaderOptions,
    add_reader_arguments,
    bag_name,
    find_bags,
    options_for_workers,
    options_from_args,
)
from endeff_ros.cli_common import (
    EXIT_FAILED,
    EXIT_OK,
    interruption,
    load_params_option,
    positive_int,
    usage_error,
)
from endeff_ros.core.cloud import box_mask
from endeff_ros.core.errors import InputError
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.types import Track
from endeff_ros.kind_eval import KindConfusion, confusion_group, confusion_table
from endeff_ros.ranking import ConfidenceRanking, summary_json
from endeff_ros.ranking import format_table as confidence_table
from endeff_ros.scoring import (
    KINDS,
    MATCH_THRESHOLD_M,
    SEEN_RADIUS_M,
    MethodScore,
    SequenceScorer,
    kinds_of_ids,
    mean_kinds_over_sequences,
    mean_over_sequences,
    nanmean,
    seen_labels,
    summary_dict,
)
from endeff_ros.tracking_metrics import TrackingScorer, tracking_group, tracking_json
from endeff_ros.tracking_metrics import format_tables as tracking_tables

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    import numpy.typing as npt

    from endeff_ros.core.types import RGBDFrame
    from endeff_ros.scoring import FrameScore, KindScore

    EstimateFn = Callable[[RGBDFrame, EndeffParams | None], Any]
    TrackerFactory = Callable[[EndeffParams | None], Any]

METHODS = ('temporal', 'single_frame')
LABELS = {'temporal': 'temporal', 'single_frame': 'single-frame'}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``endeff eval``."""
    parser.add_argument('bags', nargs='+', metavar='BAG_OR_DIR',
                        help='bags (directory with metadata.yaml, .mcap or .db3) or '
                             'directories searched for bags')
    parser.add_argument('--json', metavar='FILE', help='write the JSON report here')
    parser.add_argument('--plots', metavar='DIR', help='write PNG plots into this directory')
    parser.add_argument('--params', metavar='YAML',
                        help='parameter file (ROS 2 parameter YAML or flat mapping)')
    parser.add_argument('--jobs', type=positive_int, default=1, metavar='N',
                        help='bags evaluated in parallel processes (default 1)')
    add_reader_arguments(parser)


def _background_estimate() -> EstimateFn:
    """The default single-frame estimator with its own static background (one per bag, as
    the tracker has), so both estimators see the same foreground."""
    from endeff_ros.core.background import BackgroundModel
    from endeff_ros.core.kinds import (
        KindLabeller,
        judged_candidates,
        person_candidates,
        person_points,
    )
    from endeff_ros.core.single_frame import estimate_frame

    model, labeller = BackgroundModel(), KindLabeller()

    def estimate(frame: RGBDFrame, params: EndeffParams | None) -> Any:
        params = params or EndeffParams()
        if not params.background:
            return estimate_frame(frame, params)
        labeller.use_models(params.scored_kinds)
        estimate = estimate_frame(frame, params, background=model)
        model.observe_color(frame.color, frame.stamp_ns)
        # Its end-effectors mark the entities of the start, as the tracker's tracks do; their
        # kinds are found only while they decide what stays (a frame's shapes and kinds).
        if model.marking:
            person = (person_candidates(estimate, frame.intrinsics, labeller)
                      if model.wants_people else None)
            entities = [e.entity for e in estimate.entities for _ in e.candidates]
            model.mark(estimate.positions(), frame.intrinsics, params.pixel_stride, person,
                       person_points(estimate, entities, person),
                       None if person is None else judged_candidates(entities, person))
        return estimate

    return estimate


def _default_tracker(params: EndeffParams | None) -> Any:
    from endeff_ros.core.tracker import Tracker

    return Tracker(params)


def _positions(tracks: Sequence[Any]) -> npt.NDArray[np.float64]:
    return np.array([np.asarray(t.position, dtype=np.float64).reshape(3) for t in tracks],
                    dtype=np.float64).reshape(-1, 3)


def _predicted_unmatched(tracks: Sequence[Any], score: FrameScore) -> int:
    """Tracks left unmatched by ``score`` (false positives) whose state is predicted;
    tracks without a ``state`` (a custom tracker's) count as detections."""
    matched = set(score.matches[:, 0].tolist())
    return sum(1 for k, t in enumerate(tracks)
               if k not in matched and getattr(t, 'state', Track.DETECTED) == Track.PREDICTED)


@dataclass
class SequenceResult:
    """Everything measured on one bag."""

    name: str
    path: str
    scorers: dict[str, SequenceScorer] = field(default_factory=dict)
    stamps_ns: list[int] = field(default_factory=list)
    recalls: dict[str, list[float]] = field(default_factory=dict)
    #: False positives per scored frame and method (after a camera motion: how soon clean).
    false_positives: dict[str, list[int]] = field(default_factory=dict)
    topics: str = ''
    stats: dict[str, Any] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    input_errors: dict[str, int] = field(default_factory=dict)
    #: Temporal false positives that were predicted tracks (Track.PREDICTED), not detections.
    predicted_false_positives: int = 0
    #: Attributes from the bag's metadata (:mod:`endeff_ros.attributes`), ``{}`` if none.
    attributes: dict[str, Any] = field(default_factory=dict)
    attribute_warning: str | None = None
    #: Whether the ground-truth ids are a person's (kinds head/hand/foot) or kind ``other``.
    person: bool = False
    #: Ground-truth points of the scored frames, and those inside the foreground box (Section
    #: 3): a label outside it cannot be found, whatever the estimators do.
    gt_points: int = 0
    gt_in_box: int = 0
    #: The temporal estimator's published kinds against the matched labels' kinds.
    kind_confusion: KindConfusion = field(default_factory=KindConfusion)
    #: Time consistency of the temporal estimator's ids and positions.
    tracking: TrackingScorer = field(default_factory=TrackingScorer)
    #: The temporal estimator's published confidences against right and wrong ends.
    ranking: ConfidenceRanking = field(default_factory=ConfidenceRanking)

    @property
    def frames(self) -> int:
        """Frames processed."""
        return self.scorers['temporal'].frames

    @property
    def scored_frames(self) -> int:
        """Frames with ground truth."""
        return self.scorers['temporal'].scored_frames

    def score(self, method: str) -> MethodScore:
        """The sequence score of ``method`` ('temporal' or 'single_frame')."""
        return self.scorers[method].result()

    def kind_scores(self, method: str) -> dict[str, KindScore]:
        """Per end-effector kind of ``method``: recall and mean error."""
        return self.scorers[method].kind_result()

    def to_json(self) -> dict[str, Any]:
        """The spec's sequence entry plus extra keys."""
        out: dict[str, Any] = {'bag': self.name, 'frames': self.frames,
                               'scored_frames': self.scored_frames}
        for m in METHODS:
            out[m] = self.score(m).to_json()
        out['path'] = self.path
        out['topics'] = self.topics
        out['attributes'] = dict(self.attributes)
        if self.attribute_warning:
            out['attribute_warning'] = self.attribute_warning
        out['kinds'] = {m: {k: v.to_json() for k, v in self.kind_scores(m).items()}
                        for m in METHODS}
        out['kind_confusion'] = self.kind_confusion.to_json()
        out['counts'] = {m: summary_dict(self.scorers[m]) for m in METHODS}
        out['counts']['temporal']['predicted_false_positives'] = self.predicted_false_positives
        out['labels_in_box'] = _in_box_json(self.gt_points, self.gt_in_box)
        out['labels_seen'] = _seen_json(self.gt_points,
                                        self.scorers['temporal'].seen_points,
                                        {m: self.scorers[m].seen_recall for m in METHODS})
        out['tracking'] = tracking_json(self.tracking)
        out['confidence'] = self.ranking.to_json()
        out['estimator_input_errors'] = dict(self.input_errors)
        out['seconds'] = {k: round(v, 4) for k, v in self.seconds.items()}
        out['read_stats'] = self.stats
        out['per_frame'] = {'stamp_ns': list(self.stamps_ns),
                            **{f'{m}_recall': [_jf(r) for r in self.recalls[m]]
                               for m in METHODS},
                            **{f'{m}_false_positives': list(self.false_positives[m])
                               for m in METHODS}}
        return out


def _in_box_json(points: int, inside: int) -> dict[str, Any]:
    return {'points': points, 'inside': inside,
            'fraction': round(inside / points, 4) if points else None}


def _seen_json(points: int, seen: int, recall: dict[str, float]) -> dict[str, Any]:
    """Ground-truth points seen (:func:`~endeff_ros.scoring.seen_labels`) and each method's
    recall over them."""
    return {'points': points, 'seen': seen,
            'fraction': round(seen / points, 4) if points else None,
            'radius_m': SEEN_RADIUS_M, 'recall': {m: _jf(recall[m]) for m in METHODS}}


def _jf(value: float) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def evaluate_bag(path: str | Path, *, params: EndeffParams | None = None,
                 options: ReaderOptions | None = None, name: str | None = None,
                 estimate_fn: EstimateFn | None = None,
                 tracker_factory: TrackerFactory | None = None,
                 log: Callable[[str], None] | None = None,
                 progress: Callable[[int], None] | None = None) -> SequenceResult:
    """Run both estimators over one bag and score them (``progress(1)`` after each frame).

    ``estimate_fn(frame, params)`` (default :func:`estimate_frame`) must return an object with
    ``positions() -> (M, 3)``; ``tracker_factory(params)`` (default :class:`Tracker`) an object
    whose ``update(frame)`` returns something with ``tracks``. A frame the estimators reject
    with :class:`InputError` counts as a frame with no estimate. Raises :class:`BagError`.
    """
    estimate_fn = estimate_fn or _background_estimate()
    tracker_factory = tracker_factory or _default_tracker
    box_params = params or EndeffParams()
    path = Path(path)
    res = SequenceResult(name=name or bag_name(path), path=str(path),
                         scorers={m: SequenceScorer() for m in METHODS},
                         recalls={m: [] for m in METHODS},
                         false_positives={m: [] for m in METHODS},
                         seconds={'read': 0.0, 'temporal': 0.0, 'single_frame': 0.0},
                         input_errors={m: 0 for m in METHODS})
    with BagReader(path, options) as bag:
        assert bag.selection is not None
        res.topics = bag.selection.describe()
        if log:
            log(f'{res.name}: {res.topics}')
        res.attributes, res.attribute_warning = parse_attributes(custom_data(bag.reader),
                                                                 str(path))
        if res.attribute_warning:
            (log or _stderr)(f'warning: {res.attribute_warning}')
        res.person = is_person_sequence(res.name, res.attributes)
        ids_by_stamp = gt_ids(bag)
        tracker = tracker_factory(params)
        it = bag.frames()
        while True:
            t0 = time.perf_counter()
            try:
                frame, gt = next(it)
            except StopIteration:
                break
            t1 = time.perf_counter()
            tracks: Sequence[Any] = ()
            try:
                tracks = tracker.update(frame).tracks
                est = {'temporal': _positions(tracks)}
            except InputError:
                res.input_errors['temporal'] += 1
                est = {'temporal': np.zeros((0, 3))}
            t2 = time.perf_counter()
            try:
                est['single_frame'] = np.asarray(estimate_fn(frame, params).positions(),
                                                 dtype=np.float64).reshape(-1, 3)
            except InputError:
                res.input_errors['single_frame'] += 1
                est['single_frame'] = np.zeros((0, 3))
            t3 = time.perf_counter()
            res.seconds['read'] += t1 - t0
            res.seconds['temporal'] += t2 - t1
            res.seconds['single_frame'] += t3 - t2
            kinds = seen = None
            if gt is not None:
                seen = seen_labels(gt, frame.depth, frame.intrinsics)
            if gt is not None and frame.stamp_ns in ids_by_stamp:
                ids = ids_by_stamp[frame.stamp_ns]
                kinds = kinds_of_ids(ids, person=res.person) if len(ids) == len(gt) else None
            if progress is not None:
                progress(1)
            for m in METHODS:
                score = res.scorers[m].add(est[m], gt, kinds, seen)
                if score is not None:
                    res.recalls[m].append(score.recall)
                    res.false_positives[m].append(score.fp)
                    if m == 'temporal':
                        res.predicted_false_positives += _predicted_unmatched(tracks, score)
                        res.kind_confusion.add(tracks, kinds, score)
                        res.ranking.add([getattr(t, 'confidence', 1.0) for t in tracks],
                                        [getattr(t, 'kind', 0) for t in tracks],
                                        score.matches, score.n_gt, kinds)
                        res.tracking.add_tracks(frame.stamp_ns, gt, ids_by_stamp.get(
                            frame.stamp_ns), kinds, tracks, score, frame=res.frames)
            if gt is not None:
                res.stamps_ns.append(frame.stamp_ns)
                labels = np.asarray(gt, dtype=np.float64).reshape(-1, 3)
                res.gt_points += len(labels)
                res.gt_in_box += int(np.count_nonzero(box_mask(labels, box_params)))
        res.stats = bag.stats.to_dict()
    if res.frames == 0:
        raise BagError(path, 'no synchronised frames (colour, depth and camera info never '
                             'lined up)')
    return res


def is_person_sequence(name: str, attributes: dict[str, Any]) -> bool:
    """People in view: the attribute ``people`` > 0, else a sequence of people of the paper
    suite (its person sequences, and ``two_people`` of the generic group, whose second person's
    ids are the first's + 5)."""
    people = attributes.get('people')
    if isinstance(people, int | float) and not isinstance(people, bool):
        return people > 0
    try:
        from endeff_ros.synth.sequences import PERSON_SEQUENCES
    except Exception:  # the generator is optional for scoring
        return False
    return name.rsplit('/', 1)[-1] in (*PERSON_SEQUENCES, 'two_people')


def gt_ids(bag: BagReader) -> dict[int, npt.NDArray[np.int64]]:
    """Ground-truth ids per header stamp (ns), aligned with the positions the reader yields
    (rows with non-finite positions dropped); ``{}`` when the cloud has no ``id`` field."""
    from endeff_ros.ros import convert

    sel = bag.selection
    if sel is None or not sel.gt:
        return {}
    out: dict[int, npt.NDArray[np.int64]] = {}
    conns = [c for c in bag.reader.connections if c.topic == sel.gt]
    try:
        for conn, _, raw in bag.reader.messages(connections=conns):
            msg = bag.reader.deserialize(raw, conn.msgtype)
            points = convert.cloud_to_array(msg)
            if 'id' not in (points.dtype.names or ()):
                return {}
            finite = np.all(np.isfinite(convert.xyz(points)), axis=1)
            out[convert.stamp_to_ns(msg.header.stamp)] = points['id'][finite].astype(np.int64)
    except Exception:  # a broken cloud or storage: the frame reader reports it with context
        return {}
    return out


def _unique_names(paths: Sequence[Path]) -> list[str]:
    """Bag names, disambiguated by their parent directory where two bags share a name."""
    names = [bag_name(p) for p in paths]
    dup = {n for n in names if names.count(n) > 1}
    out = []
    for p, n in zip(paths, names, strict=True):
        parent = (p if p.is_dir() else p.parent).resolve().parent.name
        out.append(f'{parent}/{n}' if n in dup else n)
    return out


def _groups() -> dict[str, list[str]]:
    try:
        from endeff_ros.synth import GROUPS
    except Exception:  # the generator is optional for scoring
        return {}
    return {str(k): [str(s) for s in v] for k, v in dict(GROUPS).items()}


def _group_entry(inside: Sequence[SequenceResult], attribute: str | None) -> dict[str, Any]:
    """Means over the sequences of one group: the methods' scores and per-kind scores."""
    entry: dict[str, Any] = {'sequences': [r.name for r in inside]}
    if attribute is not None:
        entry['attribute'] = attribute
    for m in METHODS:
        entry[m] = mean_over_sequences([r.score(m) for r in inside]).to_json()
    entry['kinds'] = {m: {k: v.to_json() for k, v in mean_kinds_over_sequences(
        [r.kind_scores(m) for r in inside]).items()} for m in METHODS}
    entry['kind_confusion'] = confusion_group([r.kind_confusion for r in inside])
    entry['labels_seen'] = _seen_json(
        sum(r.gt_points for r in inside), sum(r.scorers['temporal'].seen_points for r in inside),
        {m: nanmean(r.scorers[m].seen_recall for r in inside) for m in METHODS})
    entry['tracking'] = tracking_group([r.tracking for r in inside])
    entry['confidence'] = summary_json([r.ranking for r in inside])
    return entry


def build_report(results: Sequence[SequenceResult], failed: Sequence[tuple[str, str]] = (),
                 params: EndeffParams | None = None) -> dict[str, Any]:
    """The JSON report: spec keys ``sequences`` and ``overall``, plus ``groups`` (the paper
    suite's named groups, then ``key=value`` per attribute value; an attribute group names its
    ``attribute``), ``kinds`` (overall per kind), ``failed``."""
    report: dict[str, Any] = {'sequences': [r.to_json() for r in results]}
    report['overall'] = {m: mean_over_sequences([r.score(m) for r in results]).to_json()
                         for m in METHODS}
    whole = _group_entry(results, None)
    report['kinds'] = whole['kinds']
    report['kind_confusion'] = whole['kind_confusion']
    report['labels_seen'] = whole['labels_seen']
    report['tracking'] = whole['tracking']
    report['confidence'] = summary_json([r.ranking for r in results], curve=True)
    report['labels_in_box'] = _in_box_json(sum(r.gt_points for r in results),
                                           sum(r.gt_in_box for r in results))
    groups = {}
    for gname, members in _groups().items():
        inside = [r for r in results if r.name.rsplit('/', 1)[-1] in members]
        if inside:
            groups[gname] = _group_entry(inside, None)
    by_name = {r.name: r for r in results}
    for key, labelled in attribute_groups([(r.name, r.attributes) for r in results]).items():
        for gname, members in labelled.items():
            groups[gname] = _group_entry([by_name[n] for n in members], key)
    report['groups'] = groups
    report['failed'] = [{'bag': b, 'error': e} for b, e in failed]
    report['match_threshold_m'] = MATCH_THRESHOLD_M
    report['conventions'] = ('recall/FPR: mean over scored frames; mean_error_m: mean over all '
                             'true-positive pairs; overall/groups: mean over sequences; kinds: '
                             'recall = true positives / ground-truth points of that kind in a '
                             'sequence, groups and overall the mean over the sequences having '
                             'that kind; null: undefined (no ground truth points or no true '
                             'positive); labels_seen: ground-truth points with depth readings '
                             f'within {SEEN_RADIUS_M} m, recall over them (a diagnostic, not '
                             'used by the scores)')
    if params is not None:
        report['params'] = params.to_dict()
    return report


def _num(v: float | None, fmt: str) -> str:
    return '-' if v is None else format(v, fmt)


def format_table(report: dict[str, Any], *, failed: bool = True) -> str:
    """Plain-text table of the report: sequences (with their split when attributes give one),
    the paper suite's groups, one section per attribute, overall; then recall and mean error
    per end-effector kind; then the failed bags, unless ``failed`` is False (``endeff eval``
    prints them on stderr, once)."""
    def cols(d: dict[str, Any]) -> str:
        return (f'{_num(d["recall"], ".3f"):>7} {_num(d["mean_error_m"], ".3f"):>7} '
                f'{_num(d["fpr"], ".3f"):>7}')

    seqs = report['sequences']
    groups = report['groups']
    splits = [str(s.get('attributes', {}).get('split', '')) for s in seqs]
    split_w = max(6, *map(len, splits)) + 1 if any(splits) else 0
    rows = [s['bag'] for s in seqs] + list(groups) + ['overall']
    width = max([len('sequence')] + [len(n) for n in rows]) + 2
    pad = f'{"":{split_w}}'
    head = (f'{"":{width}}{pad}{"":>7}{"":>7} | {"temporal":^23} | {"single-frame":^23}\n'
            f'{"sequence":{width}}{"split" if split_w else "":{split_w}}{"frames":>7}'
            f'{"scored":>7} | {"recall":>7} {"err m":>7} {"FPR":>7} | '
            f'{"recall":>7} {"err m":>7} {"FPR":>7}')
    rule = '-' * len(head.splitlines()[1])
    lines = [head, rule]
    for s, split in zip(seqs, splits, strict=True):
        lines.append(f'{s["bag"]:{width}}{split:{split_w}}{s["frames"]:>7}'
                     f'{s["scored_frames"]:>7} | {cols(s["temporal"])} | '
                     f'{cols(s["single_frame"])}')
    for section, names in group_sections(groups):
        lines.append(f'-- {section} ' + '-' * max(0, len(rule) - len(section) - 4))
        for g in names:
            d = groups[g]
            lines.append(f'{g:{width}}{pad}{"":>7}{len(d["sequences"]):>7} | '
                         f'{cols(d["temporal"])} | {cols(d["single_frame"])}')
    lines.append(rule)
    o = report['overall']
    lines.append(f'{"overall":{width}}{pad}{"":>7}{len(seqs):>7} | '
                 f'{cols(o["temporal"])} | {cols(o["single_frame"])}')
    inside = report.get('labels_in_box', {})
    if inside.get('points'):
        lines.append(f'ground-truth points inside the foreground box: {inside["inside"]} of '
                     f'{inside["points"]} ({100 * inside["fraction"]:.1f} %); no estimator finds '
                     'one outside it')
    seen = report.get('labels_seen', {})
    if seen.get('points'):
        rec = seen['recall']
        lines.append(f'ground-truth points with depth readings within {seen["radius_m"]} m '
                     f'(seen): {seen["seen"]} of {seen["points"]} '
                     f'({100 * seen["fraction"]:.1f} %); '
                     f'recall over them: temporal {_num(rec["temporal"], ".3f")}, single-frame '
                     f'{_num(rec["single_frame"], ".3f")}')
    kinds = _kind_table(report, width)
    if kinds:
        lines += ['', *kinds]
    confusion = confusion_table(report)
    if confusion:
        lines += ['', *confusion]
    tracking = tracking_tables(report, width)
    if tracking:
        lines += ['', *tracking]
    ranking = confidence_table(report, width)
    if ranking:
        lines += ['', *ranking]
    for f in report.get('failed', []) if failed else []:
        lines.append(f'FAILED {f["bag"]}: {f["error"]}')
    return '\n'.join(line.rstrip() for line in lines)


def _kind_table(report: dict[str, Any], width: int) -> list[str]:
    """Recall and mean error per kind for overall and each group, in the sections of the main
    table (empty without kinds)."""
    groups = report['groups']
    all_kinds = [report.get('kinds', {})] + [d.get('kinds', {}) for d in groups.values()]
    kinds = [k for k in KINDS if any(k in d.get(m, {}) for d in all_kinds for m in METHODS)]
    if not kinds:
        return []
    cell = 14 * len(kinds)
    head = (f'{"per kind":{width}} | {"temporal: recall / err m":^{cell}} | '
            f'{"single-frame: recall / err m":^{cell}}\n{"":{width}} | '
            + ' | '.join(''.join(f'{k:^14}' for k in kinds) for _ in METHODS))
    rule = '-' * len(head.splitlines()[1])

    def row(name: str, d: dict[str, Any]) -> str:
        cells = []
        for m in METHODS:
            per = d.get(m, {})
            cells.append(''.join(
                f'{_num(per[k]["recall"], ".3f"):>7}{_num(per[k]["mean_error_m"], ".3f"):>7}'
                if k in per else f'{"":14}' for k in kinds))
        return f'{name:{width}} | ' + ' | '.join(cells)

    lines = [head, rule, row('overall', report.get('kinds', {}))]
    for section, names in group_sections(groups):
        shown = [g for g in names if any(groups[g].get('kinds', {}).get(m) for m in METHODS)]
        if shown:
            lines.append(f'-- {section} ' + '-' * max(0, len(rule) - len(section) - 4))
            lines += [row(g, groups[g]['kinds']) for g in shown]
    return lines


def write_plots(report: dict[str, Any], out_dir: str | Path) -> list[Path]:
    """Paper-style figures: per-frame recall (black single-frame, red temporal) per sequence,
    one grid PNG, and bars of recall / mean error / FPR per sequence for both methods."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    seqs = report['sequences']
    written: list[Path] = []
    if not seqs:
        return written
    style = {'single_frame': ('black', 'single-frame'), 'temporal': ('red', 'temporal')}
    ncols = min(3, len(seqs))
    nrows = math.ceil(len(seqs) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols, 2.6 * nrows), squeeze=False)
    for ax, s in zip(axes.flat, seqs, strict=False):
        for m in ('single_frame', 'temporal'):
            y = np.array([np.nan if v is None else v for v in s['per_frame'][f'{m}_recall']],
                         dtype=float)
            color, label = style[m]
            ax.plot(np.arange(len(y)), y, color=color, lw=1.0, label=label)
        ax.set_title(s['bag'], fontsize=9)
        ax.set_ylim(-0.02, 1.05)
        ax.set_xlabel('scored frame', fontsize=8)
        ax.set_ylabel('recall', fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(seqs):]:
        ax.axis('off')
    axes.flat[0].legend(fontsize=7, loc='lower left')
    fig.tight_layout()
    written.append(out / 'per_frame_recall.png')
    fig.savefig(written[-1], dpi=110)
    plt.close(fig)

    names = [s['bag'] for s in seqs] + ['overall']
    x = np.arange(len(names))
    fig, axes = plt.subplots(3, 1, figsize=(max(6.0, 0.7 * len(names) + 2), 7.5), sharex=True)
    for ax, key, label in zip(axes, ('recall', 'mean_error_m', 'fpr'),
                              ('mean recall', 'mean error (m)', 'FPR'), strict=True):
        for k, m in enumerate(('single_frame', 'temporal')):
            vals = [s[m][key] for s in seqs] + [report['overall'][m][key]]
            vals = [np.nan if v is None else v for v in vals]
            ax.bar(x + (k - 0.5) * 0.38, vals, 0.38, color=style[m][0], label=style[m][1])
        ax.set_ylabel(label, fontsize=9)
        ax.grid(axis='y', alpha=0.3)
        if key != 'mean_error_m':
            ax.set_ylim(0.0, 1.05)
    axes[0].legend(fontsize=8)
    axes[-1].set_xticks(x, names, rotation=40, ha='right', fontsize=8)
    fig.tight_layout()
    written.append(out / 'summary_bars.png')
    fig.savefig(written[-1], dpi=110)
    plt.close(fig)

    conf = report.get('confidence', {})
    if conf.get('pr_curve', {}).get('recall'):
        fig, (pr, rel) = plt.subplots(1, 2, figsize=(8.4, 3.8))
        pr.plot(conf['pr_curve']['recall'], conf['pr_curve']['precision'], color='red')
        pr.set_xlabel('recall', fontsize=9)
        pr.set_ylabel('precision', fontsize=9)
        pr.set_title(f'temporal, AP {_num(conf["average_precision"], ".3f")}', fontsize=9)
        pr.set_xlim(0.0, 1.0)
        pr.set_ylim(0.0, 1.05)
        r = conf['reliability']
        centres = (np.arange(len(r['ends'])) + 0.5) / len(r['ends'])
        right = [np.nan if v is None else v for v in r['right']]
        rel.bar(centres, right, 1.0 / len(centres), color='red', alpha=0.6, edgecolor='black')
        rel.plot([0, 1], [0, 1], color='black', lw=0.8)
        rel.set_xlabel('published confidence', fontsize=9)
        rel.set_ylabel('fraction right', fontsize=9)
        rel.set_title(f'calibration, ECE {_num(conf["calibration_error"], ".3f")}', fontsize=9)
        for ax in (pr, rel):
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=8)
        fig.tight_layout()
        written.append(out / 'confidence.png')
        fig.savefig(written[-1], dpi=110)
        plt.close(fig)
    return written


def _eval_job(job: tuple[Path, str, EndeffParams | None, ReaderOptions, Any, Any],
              progress: Callable[[int], None] = prog.report
              ) -> SequenceResult | tuple[str, str]:
    path, name, params, options, estimate_fn, tracker_factory = job
    try:
        return evaluate_bag(path, params=params, options=options, name=name,
                            estimate_fn=estimate_fn, tracker_factory=tracker_factory,
                            log=_stderr, progress=progress)
    except BagError as err:
        return (str(path), str(err))
    except Exception as err:  # keep the other bags going; show where it broke
        if (stop := interruption(err)) is not None:
            raise stop from err
        traceback.print_exc(file=sys.stderr)
        return (str(path), f'{path}: {type(err).__name__}: {err}')


def _stderr(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def evaluate_bags(paths: Sequence[str | Path], *, params: EndeffParams | None = None,
                  options: ReaderOptions | None = None, jobs: int = 1,
                  estimate_fn: EstimateFn | None = None,
                  tracker_factory: TrackerFactory | None = None
                  ) -> tuple[dict[str, Any], list[SequenceResult]]:
    """Evaluate bags (directories are searched) and return ``(report, results)``.

    Bags that fail are listed in ``report['failed']`` with the error naming the bag and the
    problem; the others are still scored.
    """
    options = options or ReaderOptions()
    failed: list[tuple[str, str]] = []
    bags: list[Path] = []
    for arg in paths:
        try:
            bags.extend(find_bags([arg]))
        except BagError as err:
            failed.append((str(arg), str(err)))
    names = _unique_names(bags)
    workers = min(jobs, len(bags))
    options = options_for_workers(options, workers)
    job_list = [(p, n, params, options, estimate_fn, tracker_factory)
                for p, n in zip(bags, names, strict=True)]
    total = prog.count_frames(bags, options) if sys.stderr.isatty() else 0
    with prog.progress_bar(total, desc='endeff eval') as bar:
        if workers > 1:
            outcomes = prog.map_in_workers(_eval_job, job_list, workers, bar)
        else:
            outcomes = [_eval_job(j, bar.update) for j in job_list]
    results = [o for o in outcomes if isinstance(o, SequenceResult)]
    failed.extend(o for o in outcomes if not isinstance(o, SequenceResult))
    return build_report(results, failed, params), results


def run(args: argparse.Namespace) -> int:
    """``endeff eval``: print the table, write JSON and plots; 1 if any bag failed, 2 if an
    input or output path cannot be used (then nothing is read)."""
    params = load_params_option(args.params, 'endeff eval')
    # Output and input problems end the command before any bag is read.
    check_output_option(args.json, 'endeff eval')
    check_output_option(args.plots, 'endeff eval', kind='dir')
    try:
        bags = find_bags(args.bags)
    except BagError as err:
        raise usage_error('endeff eval', str(err)) from err
    report, _ = evaluate_bags(bags, params=params, options=options_from_args(args),
                              jobs=args.jobs)
    if report['sequences']:
        print(format_table(report, failed=False))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        with open(args.json, 'w', encoding='utf-8') as fh:
            json.dump(report, fh, indent=1, allow_nan=False)
            fh.write('\n')
        _stderr(f'wrote {args.json}')
    if args.plots:
        try:
            for p in write_plots(report, args.plots):
                _stderr(f'wrote {p}')
        except ImportError as err:  # matplotlib is optional on a robot
            _stderr(f'endeff eval: no plots: {err} (install python3-matplotlib)')
    for f in report['failed']:
        _stderr(f'endeff eval: FAILED {f["error"]}')
    return EXIT_FAILED if report['failed'] or not report['sequences'] else EXIT_OK
