"""``endeff eval``: score the temporal and the single-frame estimator on benchmark bags.

Every bag in the benchmark-bag form (``/work/shared/spec/benchmark-bags.md``), written by anyone,
is scored: frames are read and synchronised by :mod:`endeff_ros.bag.reader`, each frame goes to
the temporal :class:`~endeff_ros.core.tracker.Tracker` and to the single-frame
:func:`~endeff_ros.core.single_frame.estimate_frame` in the same run, and both are scored with
:mod:`endeff_ros.scoring` (Section 6.1, Eqs. 10-12).

Output: a table on stdout, optionally the JSON report (``--json``, the spec's form plus extra
keys ``per_frame``, ``groups``, ``failed``...) and plots (``--plots``). Progress and the topic
choice per bag go to stderr. Exit status 1 if any bag failed, else 0.

No ROS import: this runs without rclpy.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import traceback
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from endeff_ros.bag.errors import BagError
from endeff_ros.bag.reader import (
    BagReader,
    ReaderOptions,
    add_reader_arguments,
    bag_name,
    find_bags,
    options_from_args,
)
from endeff_ros.cli import load_params_option
from endeff_ros.core.errors import InputError
from endeff_ros.core.types import Track
from endeff_ros.scoring import (
    MATCH_THRESHOLD_M,
    MethodScore,
    SequenceScorer,
    mean_over_sequences,
    summary_dict,
)

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    import numpy.typing as npt

    from endeff_ros.core.params import EndeffParams
    from endeff_ros.core.types import RGBDFrame
    from endeff_ros.scoring import FrameScore

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
    parser.add_argument('--jobs', type=int, default=1, metavar='N',
                        help='bags evaluated in parallel processes (default 1)')
    add_reader_arguments(parser)


def _default_estimate(frame: RGBDFrame, params: EndeffParams | None) -> Any:
    from endeff_ros.core.single_frame import estimate_frame

    return estimate_frame(frame, params)


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
    topics: str = ''
    stats: dict[str, Any] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    input_errors: dict[str, int] = field(default_factory=dict)
    #: Temporal false positives that were predicted tracks (Track.PREDICTED), not detections.
    predicted_false_positives: int = 0

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

    def to_json(self) -> dict[str, Any]:
        """The spec's sequence entry plus extra keys."""
        out: dict[str, Any] = {'bag': self.name, 'frames': self.frames,
                               'scored_frames': self.scored_frames}
        for m in METHODS:
            out[m] = self.score(m).to_json()
        out['path'] = self.path
        out['topics'] = self.topics
        out['counts'] = {m: summary_dict(self.scorers[m]) for m in METHODS}
        out['counts']['temporal']['predicted_false_positives'] = self.predicted_false_positives
        out['estimator_input_errors'] = dict(self.input_errors)
        out['seconds'] = {k: round(v, 4) for k, v in self.seconds.items()}
        out['read_stats'] = self.stats
        out['per_frame'] = {'stamp_ns': list(self.stamps_ns),
                            **{f'{m}_recall': [_jf(r) for r in self.recalls[m]]
                               for m in METHODS}}
        return out


def _jf(value: float) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def evaluate_bag(path: str | Path, *, params: EndeffParams | None = None,
                 options: ReaderOptions | None = None, name: str | None = None,
                 estimate_fn: EstimateFn | None = None,
                 tracker_factory: TrackerFactory | None = None,
                 log: Callable[[str], None] | None = None) -> SequenceResult:
    """Run both estimators over one bag and score them.

    ``estimate_fn(frame, params)`` (default :func:`estimate_frame`) must return an object with
    ``positions() -> (M, 3)``; ``tracker_factory(params)`` (default :class:`Tracker`) an object
    whose ``update(frame)`` returns something with ``tracks``. A frame the estimators reject
    with :class:`InputError` counts as a frame with no estimate. Raises :class:`BagError`.
    """
    estimate_fn = estimate_fn or _default_estimate
    tracker_factory = tracker_factory or _default_tracker
    path = Path(path)
    res = SequenceResult(name=name or bag_name(path), path=str(path),
                         scorers={m: SequenceScorer() for m in METHODS},
                         recalls={m: [] for m in METHODS},
                         seconds={'read': 0.0, 'temporal': 0.0, 'single_frame': 0.0},
                         input_errors={m: 0 for m in METHODS})
    with BagReader(path, options) as bag:
        assert bag.selection is not None
        res.topics = bag.selection.describe()
        if log:
            log(f'{res.name}: {res.topics}')
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
            for m in METHODS:
                score = res.scorers[m].add(est[m], gt)
                if score is not None:
                    res.recalls[m].append(score.recall)
                    if m == 'temporal':
                        res.predicted_false_positives += _predicted_unmatched(tracks, score)
            if gt is not None:
                res.stamps_ns.append(frame.stamp_ns)
        res.stats = bag.stats.to_dict()
    if res.frames == 0:
        raise BagError(path, 'no synchronised frames (colour, depth and camera info never '
                             'lined up)')
    return res


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


def build_report(results: Sequence[SequenceResult], failed: Sequence[tuple[str, str]] = (),
                 params: EndeffParams | None = None) -> dict[str, Any]:
    """The JSON report: spec keys ``sequences`` and ``overall``, plus ``groups``, ``failed``."""
    report: dict[str, Any] = {'sequences': [r.to_json() for r in results]}
    report['overall'] = {m: mean_over_sequences([r.score(m) for r in results]).to_json()
                         for m in METHODS}
    groups = {}
    for gname, members in _groups().items():
        inside = [r for r in results if r.name.rsplit('/', 1)[-1] in members]
        if inside:
            groups[gname] = {'sequences': [r.name for r in inside],
                             **{m: mean_over_sequences([r.score(m) for r in inside]).to_json()
                                for m in METHODS}}
    report['groups'] = groups
    report['failed'] = [{'bag': b, 'error': e} for b, e in failed]
    report['match_threshold_m'] = MATCH_THRESHOLD_M
    report['conventions'] = ('recall/FPR: mean over scored frames; mean_error_m: mean over all '
                             'true-positive pairs; overall/groups: mean over sequences; null: '
                             'undefined (no ground truth points or no true positive)')
    if params is not None:
        report['params'] = params.to_dict()
    return report


def format_table(report: dict[str, Any]) -> str:
    """Plain-text table of the report."""
    def num(v: float | None, fmt: str) -> str:
        return '-' if v is None else format(v, fmt)

    def cols(d: dict[str, Any]) -> str:
        return (f'{num(d["recall"], ".3f"):>7} {num(d["mean_error_m"], ".3f"):>7} '
                f'{num(d["fpr"], ".3f"):>7}')

    rows = [r['bag'] for r in report['sequences']] + list(report['groups']) + ['overall']
    width = max([len('sequence')] + [len(n) for n in rows]) + 2
    head = (f'{"":{width}}{"":>7}{"":>7} | {"temporal":^23} | {"single-frame":^23}\n'
            f'{"sequence":{width}}{"frames":>7}{"scored":>7} | '
            f'{"recall":>7} {"err m":>7} {"FPR":>7} | {"recall":>7} {"err m":>7} {"FPR":>7}')
    lines = [head, '-' * len(head.splitlines()[1])]
    for r in report['sequences']:
        lines.append(f'{r["bag"]:{width}}{r["frames"]:>7}{r["scored_frames"]:>7} | '
                     f'{cols(r["temporal"])} | {cols(r["single_frame"])}')
    if report['groups']:
        lines.append('-' * len(lines[1]))
        for g, d in report['groups'].items():
            lines.append(f'{g:{width}}{"":>7}{len(d["sequences"]):>7} | '
                         f'{cols(d["temporal"])} | {cols(d["single_frame"])}')
    lines.append('-' * len(lines[1]))
    o = report['overall']
    lines.append(f'{"overall":{width}}{"":>7}{len(report["sequences"]):>7} | '
                 f'{cols(o["temporal"])} | {cols(o["single_frame"])}')
    for f in report.get('failed', []):
        lines.append(f'FAILED {f["bag"]}: {f["error"]}')
    return '\n'.join(lines)


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
    return written


def _eval_job(job: tuple[Path, str, EndeffParams | None, ReaderOptions, Any, Any]
              ) -> SequenceResult | tuple[str, str]:
    path, name, params, options, estimate_fn, tracker_factory = job
    try:
        return evaluate_bag(path, params=params, options=options, name=name,
                            estimate_fn=estimate_fn, tracker_factory=tracker_factory,
                            log=_stderr)
    except BagError as err:
        return (str(path), str(err))
    except Exception as err:  # keep the other bags going; show where it broke
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
    job_list = [(p, n, params, options, estimate_fn, tracker_factory)
                for p, n in zip(bags, names, strict=True)]
    if jobs > 1 and len(job_list) > 1:
        with ProcessPoolExecutor(max_workers=min(jobs, len(job_list))) as pool:
            outcomes = list(pool.map(_eval_job, job_list))
    else:
        outcomes = [_eval_job(j) for j in job_list]
    results = [o for o in outcomes if isinstance(o, SequenceResult)]
    failed.extend(o for o in outcomes if not isinstance(o, SequenceResult))
    return build_report(results, failed, params), results


def run(args: argparse.Namespace) -> int:
    """``endeff eval``: print the table, write JSON and plots; 1 if any bag failed."""
    params = load_params_option(args.params, 'endeff eval')
    jobs = args.jobs if args.jobs and args.jobs > 0 else (os.cpu_count() or 1)
    report, _ = evaluate_bags(args.bags, params=params, options=options_from_args(args),
                              jobs=jobs)
    print(format_table(report))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        with open(args.json, 'w', encoding='utf-8') as fh:
            json.dump(report, fh, indent=1, allow_nan=False)
            fh.write('\n')
        _stderr(f'wrote {args.json}')
    if args.plots:
        for p in write_plots(report, args.plots):
            _stderr(f'wrote {p}')
    for f in report['failed']:
        _stderr(f'endeff eval: FAILED {f["error"]}')
    return 1 if report['failed'] or not report['sequences'] else 0
