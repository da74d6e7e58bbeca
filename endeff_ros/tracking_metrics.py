"""Time consistency of tracked end-effectors: do ids hold, and do positions move smoothly?

The paper's scores (:mod:`endeff_ros.scoring`, Eqs. 10-12) look at one frame at a time; a
subscriber following "the hand with id 7" also needs the id to stay on that hand and its
position to move as the hand does. Per ground-truth end-effector (the cloud's ``id``, else
its row), each frame's one-to-one matching of :func:`~endeff_ros.scoring.score_frame`
(Hungarian, within 0.15 m) gives the track id that follows it, if any:

- **id switches per minute**: times the matched track id differs from the one matched last
  (frames without a match between them do not break the chain), over the minutes the
  end-effectors are listed in the ground truth (each end-effector's frames times the frame
  period, summed);
- **ids per end-effector**: distinct track ids matched to an end-effector, mean over those
  matched at least once;
- **IDF1** (Ristani et al., ECCV 2016 workshops, as the MOT benchmarks compute it): one global
  one-to-one assignment between ground-truth ids and track ids over the whole sequence
  maximising the frames in which the pair lies within 0.15 m (IDTP); every other
  ground-truth point is an IDFN, every other track point of a scored frame an IDFP;
  IDF1 = 2 IDTP / (2 IDTP + IDFP + IDFN);
- **jitter**: mean |e_t - e_{t-1}| of the error vector e = published - truth over pairs of
  consecutive frames in which the end-effector is matched to the same id (noise that the
  truth does not have; a constant offset costs nothing);
- **acceleration error**: mean |(p_{t+1} - 2 p_t + p_{t-1}) - (g_{t+1} - 2 g_t + g_{t-1})|
  over triples of consecutive frames matched to the same id (p published, g the truth), at
  the bag's frame rate: what differentiating the positions twice would get wrong.

Per kind (head, hand, foot, other) the same figures over the end-effectors of that kind; the
IDFP of a kind are the unmatched points of the tracks the assignment gave to its
end-effectors (a track given to none counts in the sequence's IDFP only). Groups and the
overall figures are means over sequences, as for the paper's scores.

Pure numpy/scipy: no ROS imports.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .attributes import group_sections
from .core.assignment import min_cost_assignment
from .scoring import KINDS, MATCH_THRESHOLD_M, nanmean

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy.typing as npt

    from .scoring import FrameScore

#: Figures of one sequence (or kind), in report order: key, table header, scale, format.
FIGURES = (('id_switches_per_min', 'sw/min', 1.0, '.2f'),
           ('ids_per_end_effector', 'ids/ee', 1.0, '.2f'),
           ('idf1', 'IDF1', 1.0, '.3f'),
           ('jitter_m', 'jit mm', 1e3, '.1f'),
           ('accel_error_m', 'acc mm', 1e3, '.1f'))
#: Counts summed rather than averaged over sequences.
COUNTS = ('id_switches', 'end_effectors', 'end_effector_minutes', 'idtp', 'idfp', 'idfn')


@dataclass
class TrackingScorer:
    """Accumulates one sequence's matches; :meth:`result` computes the figures.

    Call :meth:`add` once per scored frame, in frame order, with the frame's one-to-one
    matches (estimate index, ground-truth index) of :func:`~endeff_ros.scoring.score_frame`.
    """

    threshold: float = MATCH_THRESHOLD_M
    frame: int = 0
    stamps_ns: list[int] = field(default_factory=list)
    #: Per ground-truth point of each frame: frame index, key, kind, truth xyz, track id
    #: (-1 unmatched), published xyz (nan unmatched).
    rows: list[tuple[npt.NDArray, ...]] = field(default_factory=list)
    #: (ground-truth key, track id) -> frames within the threshold (IDTP candidates).
    pairs: dict[tuple[int, int], int] = field(default_factory=dict)
    #: Track id -> its points in the scored frames.
    track_points: dict[int, int] = field(default_factory=dict)
    _cached: tuple[int, dict[str, dict[str, float]]] | None = field(default=None, repr=False)

    def add(self, stamp_ns: int, ground_truth: npt.ArrayLike, gt_ids: npt.ArrayLike | None,
            kinds: npt.ArrayLike | None, positions: npt.ArrayLike, track_ids: npt.ArrayLike,
            matches: npt.ArrayLike, *, frame: int | None = None) -> None:
        """One scored frame: (N, 3) truth with its ids (None: the row is the id) and kinds
        (None: ``other``), (M, 3) published positions with their track ids, and the (K, 2)
        (estimate, truth) index pairs matched. ``frame``: the frame's index in the sequence
        (default: one after the last added), so that frames without ground truth in between
        break the runs of consecutive frames."""
        self.frame = self.frame + 1 if frame is None else int(frame)
        gt = np.asarray(ground_truth, dtype=np.float64).reshape(-1, 3)
        est = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        tid = np.asarray(track_ids, dtype=np.int64).reshape(-1)
        n = len(gt)
        keys = (np.arange(n, dtype=np.int64) if gt_ids is None
                else np.asarray(gt_ids, dtype=np.int64).reshape(-1))
        kind = (np.full(n, 'other') if kinds is None else np.asarray(kinds).reshape(-1))
        m = np.asarray(matches, dtype=np.intp).reshape(-1, 2)
        matched_id = np.full(n, -1, dtype=np.int64)
        matched_pos = np.full((n, 3), np.nan)
        matched_id[m[:, 1]] = tid[m[:, 0]]
        matched_pos[m[:, 1]] = est[m[:, 0]]
        self.stamps_ns.append(int(stamp_ns))
        self.rows.append((np.full(n, self.frame), keys, kind.astype(str), gt, matched_id,
                          matched_pos))
        for t in tid.tolist():
            self.track_points[t] = self.track_points.get(t, 0) + 1
        if n and len(est):
            close = np.linalg.norm(gt[:, None] - est[None], axis=2) <= self.threshold
            for g, e in zip(*np.nonzero(close), strict=True):
                key = (int(keys[g]), int(tid[e]))
                self.pairs[key] = self.pairs.get(key, 0) + 1

    def add_tracks(self, stamp_ns: int, ground_truth: npt.ArrayLike, gt_ids: npt.ArrayLike | None,
                   kinds: npt.ArrayLike | None, tracks: Sequence[Any], score: FrameScore, *,
                   frame: int | None = None) -> None:
        """:meth:`add` for published tracks (``position``, ``id``: a tracker without ids
        gives each estimate its row) scored as ``score``; ids that do not line up with the
        truth's rows are not used."""
        gt = np.asarray(ground_truth, dtype=np.float64).reshape(-1, 3)
        ids = None if gt_ids is None or len(gt_ids) != len(gt) else gt_ids
        positions = np.array([np.asarray(t.position, dtype=np.float64).reshape(3)
                              for t in tracks]).reshape(-1, 3)
        track_ids = [int(getattr(t, 'id', k)) for k, t in enumerate(tracks)]
        self.add(stamp_ns, gt, ids, kinds, positions, track_ids, score.matches, frame=frame)

    def frame_period_ns(self) -> float:
        """Median interval between consecutive scored frames (nan with fewer than two)."""
        if len(self.stamps_ns) < 2:
            return math.nan
        return float(np.median(np.diff(np.asarray(self.stamps_ns, dtype=np.float64))))

    def result(self) -> dict[str, dict[str, float]]:
        """``{'all': figures, kind: figures}``: :data:`FIGURES` and :data:`COUNTS` keys, nan
        where undefined (no end-effector, no consecutive same-id frames)."""
        if self._cached is None or self._cached[0] != len(self.rows):
            self._cached = (len(self.rows), self._compute())
        return self._cached[1]

    def _compute(self) -> dict[str, dict[str, float]]:
        if not self.rows:
            return {'all': _figures(_empty())}
        cols = [np.concatenate([r[i] for r in self.rows]) for i in range(6)]
        frame, key, kind, gt, tid, pos = cols
        order = np.lexsort((frame, key))
        frame, key, kind, gt, tid, pos = (c[order] for c in (frame, key, kind, gt, tid, pos))
        kind_of = dict(zip(key.tolist(), kind.tolist(), strict=False))
        per_key = _per_key(frame, key, gt, tid, pos)
        gt_count = {int(k): int(c) for k, c in zip(*np.unique(key, return_counts=True),
                                                     strict=True)}
        assigned = self._assign()
        period_min = self.frame_period_ns() / 60e9
        out = {}
        kinds = sorted(set(kind_of.values()), key=lambda k: (KINDS.index(k) if k in KINDS
                                                             else len(KINDS), k))
        for name in ('all', *kinds):
            keys = [k for k in per_key if name == 'all' or kind_of[k] == name]
            acc = _empty()
            for k in keys:
                s = per_key[k]
                acc['id_switches'] += s['switches']
                acc['ids'].append(s['ids'])
                acc['jitter'].append(s['jitter'])
                acc['accel'].append(s['accel'])
                acc['end_effector_minutes'] += gt_count[k] * period_min
                acc['idfn'] += gt_count[k]
                if k in assigned:
                    t = assigned[k]
                    tp = self.pairs.get((k, t), 0)
                    acc['idtp'] += tp
                    acc['idfn'] -= tp
                    acc['idfp'] += self.track_points.get(t, 0) - tp
            acc['end_effectors'] = len(keys)
            if name == 'all':  # tracks given to no end-effector: false all the same
                given = set(assigned.values())
                acc['idfp'] += sum(c for t, c in self.track_points.items() if t not in given)
            out[name] = _figures(acc)
        return out

    def _assign(self) -> dict[int, int]:
        """Ground-truth key -> track id of the global IDTP-maximising one-to-one assignment
        (pairs that never came within the threshold are not assigned)."""
        if not self.pairs:
            return {}
        gkeys = sorted({g for g, _ in self.pairs})
        tkeys = sorted({t for _, t in self.pairs})
        gi = {g: i for i, g in enumerate(gkeys)}
        ti = {t: i for i, t in enumerate(tkeys)}
        count = np.zeros((len(gkeys), len(tkeys)))
        for (g, t), c in self.pairs.items():
            count[gi[g], ti[t]] = c
        rows, cols = min_cost_assignment(-count)
        return {gkeys[r]: tkeys[c] for r, c in zip(rows, cols, strict=True) if count[r, c] > 0}


def _empty() -> dict[str, Any]:
    return {'id_switches': 0, 'ids': [], 'jitter': [], 'accel': [],
            'end_effector_minutes': 0.0, 'end_effectors': 0, 'idtp': 0, 'idfp': 0, 'idfn': 0}


def _per_key(frame: npt.NDArray, key: npt.NDArray, gt: npt.NDArray, tid: npt.NDArray,
             pos: npt.NDArray) -> dict[int, dict[str, Any]]:
    """Per ground-truth key (rows sorted by key, then frame): switches, distinct ids, and the
    jitter and acceleration-error terms (arrays) of its consecutive same-id frames."""
    out = {}
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    ends = np.r_[starts[1:], len(key)]
    for a, b in zip(starts, ends, strict=True):
        f, ids, err = frame[a:b], tid[a:b], pos[a:b] - gt[a:b]
        g, p = gt[a:b], pos[a:b]
        seen = ids[ids >= 0]
        switches = int(np.count_nonzero(seen[1:] != seen[:-1]))
        # Consecutive frames, matched in both to the same id.
        same1 = (np.diff(f) == 1) & (ids[1:] == ids[:-1]) & (ids[1:] >= 0)
        jitter = np.linalg.norm(err[1:] - err[:-1], axis=1)[same1]
        same2 = same1[1:] & same1[:-1]
        acc = (p[2:] - 2 * p[1:-1] + p[:-2]) - (g[2:] - 2 * g[1:-1] + g[:-2])
        accel = np.linalg.norm(acc, axis=1)[same2] if len(acc) else np.zeros(0)
        out[int(key[a])] = {'switches': switches, 'ids': len(np.unique(seen)) if seen.size
                            else math.nan, 'jitter': jitter, 'accel': accel}
    return out


def _figures(acc: dict[str, Any]) -> dict[str, float]:
    jitter = np.concatenate(acc['jitter']) if acc['jitter'] else np.zeros(0)
    accel = np.concatenate(acc['accel']) if acc['accel'] else np.zeros(0)
    minutes = acc['end_effector_minutes']
    denom = 2 * acc['idtp'] + acc['idfp'] + acc['idfn']
    return {'id_switches_per_min': acc['id_switches'] / minutes if minutes > 0 else math.nan,
            'ids_per_end_effector': nanmean(acc['ids']),
            'idf1': 2 * acc['idtp'] / denom if denom else math.nan,
            'jitter_m': float(jitter.mean()) if jitter.size else math.nan,
            'accel_error_m': float(accel.mean()) if accel.size else math.nan,
            'id_switches': int(acc['id_switches']), 'end_effectors': int(acc['end_effectors']),
            'end_effector_minutes': float(minutes), 'idtp': int(acc['idtp']),
            'idfp': int(acc['idfp']), 'idfn': int(acc['idfn'])}


def mean_over_sequences(results: Sequence[dict[str, dict[str, float]]],
                        ) -> dict[str, dict[str, float]]:
    """Per ``'all'`` and per kind: each figure's mean over the sequences that have it, the
    counts summed."""
    names = sorted({n for r in results for n in r},
                   key=lambda k: (-1 if k == 'all' else KINDS.index(k) if k in KINDS
                                  else len(KINDS), k))
    out = {}
    for name in names:
        have = [r[name] for r in results if name in r]
        entry: dict[str, float] = {f: nanmean(h[f] for h in have) for f, *_ in FIGURES}
        entry.update({c: sum(h[c] for h in have) for c in COUNTS})
        out[name] = entry
    return out


def to_json(result: dict[str, dict[str, float]]) -> dict[str, Any]:
    """``{figures and counts of 'all', 'kinds': {kind: ...}}``, None for undefined values."""
    def clean(d: dict[str, float]) -> dict[str, Any]:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in d.items()}

    out = clean(result.get('all', _figures(_empty())))
    out['kinds'] = {k: clean(v) for k, v in result.items() if k != 'all'}
    return out


def tracking_json(scorer: TrackingScorer) -> dict[str, Any]:
    """A sequence's report entry."""
    return to_json(scorer.result())


def tracking_group(scorers: Sequence[TrackingScorer]) -> dict[str, Any]:
    """The report entry of a group of sequences (or all of them): means over sequences."""
    return to_json(mean_over_sequences([s.result() for s in scorers]))


def _cell(v: float | None, scale: float, fmt: str) -> str:
    return '-' if v is None else format(v * scale, fmt)


def format_tables(report: dict[str, Any], width: int) -> list[str]:
    """The report's time-consistency figures: one row per sequence, group and overall, then
    per kind (overall and groups); empty when the report holds none."""
    overall = report.get('tracking')
    if not overall:
        return []
    heads = ''.join(f'{h:>8}' for _, h, _, _ in FIGURES)
    head = f'{"time consistency (temporal)":{width}} |{heads}'
    rule = '-' * len(head)

    def row(name: str, d: dict[str, Any]) -> str:
        return f'{name:{width}} |' + ''.join(f'{_cell(d.get(k), s, f):>8}'
                                            for k, _, s, f in FIGURES)

    lines = [head, rule]
    lines += [row(s['bag'], s['tracking']) for s in report['sequences'] if 'tracking' in s]
    groups = report.get('groups', {})
    sections = group_sections(groups, 'tracking')
    for section, names in sections:
        lines.append(f'-- {section} ' + '-' * max(0, len(rule) - len(section) - 4))
        lines += [row(g, groups[g]['tracking']) for g in names]
    lines += [rule, row('overall', overall)]
    kinds = [k for k in KINDS if k in overall.get('kinds', {})]
    if kinds:
        short = FIGURES[:4]
        cell = 7 * len(short)
        khead = (f'{"per kind":{width}} | '
                 + ' | '.join(f'{k + ": " + "/".join(h for _, h, _, _ in short):^{cell}}'
                              for k in kinds))
        lines += ['', khead, '-' * len(khead)]

        def krow(name: str, d: dict[str, Any]) -> str:
            per = d.get('kinds', {})
            return f'{name:{width}} | ' + ' | '.join(
                ''.join(f'{_cell(per[k].get(f), s, fmt):>7}' for f, _, s, fmt in short)
                if k in per else ' ' * cell for k in kinds)

        lines.append(krow('overall', overall))
        for section, names in sections:
            lines.append(f'-- {section} ' + '-' * max(0, len(khead) - len(section) - 4))
            lines += [krow(g, groups[g]['tracking']) for g in names]
    return lines
