"""Where the temporal estimator's id switches come from: each switch by its cause.

Per ground-truth end-effector (its ``id`` field, else its row), frames matched as ``endeff
eval`` matches them (Hungarian within 0.15 m, :mod:`endeff_ros.tracking_metrics`): a switch is
a match to track B after the last match was to track A != B. Its cause, in this order:

- ``lost_new``: A was dropped (``lost_<why>`` names why, as :mod:`tools.track_history` does:
  ``left``, ``unconfirmed``, ``short``, ``expired``, ``duplicate``) and B started after A's
  last match: the end lost and found again under a new id;
- ``lost_other``: A was dropped and B is an older track that came over;
- ``swap``: A is still published and matched to another end-effector (the tracks of two
  limbs exchanged their ends: a case A or B pairing across limbs);
- ``duplicate_new``: A is still published, matched to nothing, and B started after A's last
  match: a second track on the same end took it over in the frame's matching;
- ``duplicate_old``: as ``duplicate_new`` with an older B.

Each cause counts per kind (head, hand, foot; ``other``); ``entity_changed`` counts the
switches whose B lies in another entity than A did at its last match, and ``gap`` the frames
between the two matches (1: consecutive), as a histogram (1, 2-3, 4-9, 10+), overall and per
cause; a duplicate's A is on its prediction or detected (``duplicate_*:old_predicted`` /
``old_detected``). ``births_beside_predicted`` counts, per distance, the tracks born beside
a predicted one of their entity and who then holds its truth (:class:`BirthTally`).
``windows`` gives, per stretch of a bag's frames (:data:`WINDOWS`), its
switches and its end-effector minutes (labels at 30 Hz), and their ratio: whether switches
come with a track's start or through the whole bag. A tally for the tracker's work, not a
score.

    python -m tools.id_switches BAG_OR_DIR [...] [--every N] [--params YAML] [--jobs 2]
                                [--json OUT]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from endeff_ros.cli_common import print_json
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.types import Track
from endeff_ros.scoring import score_frame
from tools.per_bag import parse_bag_args, run_per_bag
from tools.track_history import _RecordingTracker, tracked_frames

CAUSES = ('lost_new', 'lost_other', 'swap', 'duplicate_new', 'duplicate_old')
GAPS = ((1, 1), (2, 3), (4, 9), (10, 10**9))
#: Stretches of a bag, in frames from its first: the first second and the rest.
WINDOWS = ((0, 10), (10, 30), (30, 10**9))


#: A track born within this distance (m) of a track of its entity on its prediction is born
#: beside it (:class:`BirthTally`); the tally's distance bins end at these bounds.
BIRTH_BINS = (0.1, 0.2, 0.3, 0.5)
#: Frames from a birth within which the truth the predicted track last matched must go to one
#: of the two for an outcome (else ``none``).
BIRTH_OUTCOME_FRAMES = 5
#: What :class:`BirthTally` counts: the new track holds the truth, the predicted one, neither.
BIRTH_OUTCOMES = ('A', 'B', 'none')


def _birth_bin(distance: float) -> str:
    lo = 0.0
    for hi in BIRTH_BINS:
        if distance < hi:
            return f'{lo:g}-{hi:g} m'
        lo = hi
    return f'{lo:g}+ m'


class BirthTally:
    """New tracks born beside a track of their entity that is on its prediction, and who then
    holds the truth the predicted track last matched: the new track (``B``), the predicted
    one (``A``) or neither within :data:`BIRTH_OUTCOME_FRAMES` frames (``none``), per bin of
    their distance at the birth. Whether a rule "a track born beside a prediction takes its
    id" would remove the duplicates' switches or add as many: the evidence such a decision
    needs, counted before it is made."""

    def __init__(self) -> None:
        self.counts: dict[str, dict[str, int]] = {}
        self._previous: set[int] = set()
        self._key_of: dict[int, int] = {}  # track id -> the truth key it last matched
        self._pending: list[tuple[int, int, int, int, str]] = []

    def births(self, index: int, states: list[Any]) -> None:
        """The births of frame ``index``; ``states``: every track after the frame's update
        (``id``, ``entity``, ``position``, ``detected``)."""
        predicted = [t for t in states if t.id in self._previous and not t.detected
                     and t.id in self._key_of]
        for b in (t for t in states if t.id not in self._previous):
            near = [(float(np.linalg.norm(np.asarray(a.position) - np.asarray(b.position))),
                     a.id) for a in predicted if a.entity == b.entity]
            if near:
                distance, a = min(near)
                if distance < BIRTH_BINS[-1]:
                    self._pending.append((index, a, b.id, self._key_of[a],
                                          _birth_bin(distance)))
        self._previous = {t.id for t in states}

    def matched(self, index: int, owner: dict[int, int]) -> None:
        """The matches of frame ``index`` (after :meth:`births`): truth key -> track id."""
        self._key_of.update({track: key for key, track in owner.items()})
        waiting = []
        for event in self._pending:
            born, a, b, key, name = event
            who = owner.get(key)
            outcome = 'B' if who == b else 'A' if who == a else None
            if outcome is None and index - born < BIRTH_OUTCOME_FRAMES - 1:
                waiting.append(event)
            else:
                self._count(name, outcome or 'none')
        self._pending = waiting

    def close(self) -> dict[str, dict[str, int]]:
        """The counts, births still waiting at the bag's end counted as ``none``."""
        for *_, name in self._pending:
            self._count(name, 'none')
        self._pending = []
        return self.counts

    def _count(self, name: str, outcome: str) -> None:
        self.counts.setdefault(name, dict.fromkeys(BIRTH_OUTCOMES, 0))[outcome] += 1


def _gap_name(gap: int) -> str:
    for lo, hi in GAPS:
        if lo <= gap <= hi:
            return f'{lo}' if lo == hi else f'{lo}+' if hi > 10**6 else f'{lo}-{hi}'
    return '?'


def _window(index: int) -> str:
    """The name of the stretch of :data:`WINDOWS` that frame ``index`` lies in."""
    lo, hi = next(w for w in WINDOWS if w[0] <= index < w[1])
    return f'frames_{lo}+' if hi > 10**6 else f'frames_{lo}-{hi - 1}'


def check_bag(bag: Path, params: EndeffParams | None = None) -> dict[str, Any]:
    """Switch counts of one bag, per kind and cause."""
    tracker = _RecordingTracker(params or EndeffParams())
    counts: dict[str, dict[str, int]] = {}
    detail: dict[str, int] = {}
    last: dict[int, tuple[int, int, int]] = {}  # gt key -> (frame, track id, entity)
    born: dict[int, int] = {}  # track id -> frame it was first published (this life)
    why_dropped: dict[int, str] = {}
    windows = {_window(lo): {'switches': 0, 'labels': 0} for lo, _ in WINDOWS}
    matches = 0
    births = BirthTally()
    for index, tracks, dropped, gt, keys, kinds, _ in tracked_frames(bag, tracker):
        births.births(index, tracker._tracks)  # noqa: SLF001 - unpublished tracks too
        for track_id, why in dropped.items():
            why_dropped[track_id] = why
            born.pop(track_id, None)
        for t in tracks:
            born.setdefault(t.id, index)
        if gt is None:
            continue
        windows[_window(index)]['labels'] += len(gt)
        pos = np.array([t.position for t in tracks]).reshape(-1, 3)
        score = score_frame(pos, gt)
        by_id = {t.id: t for t in tracks}
        matched_tracks = {tracks[e].id for e, _ in score.matches}
        births.matched(index, {int(keys[g]): tracks[e].id for e, g in score.matches})
        for e, g in score.matches:
            key, track = int(keys[g]), tracks[e]
            matches += 1
            prev = last.get(key)
            last[key] = (index, track.id, track.entity)
            if prev is None or prev[1] == track.id:
                continue
            t0, a, entity = prev
            if a not in by_id:
                cause = 'lost_new' if born[track.id] > t0 else 'lost_other'
                detail_key = f'{cause}:{why_dropped.get(a, "unknown")}'
            elif a in matched_tracks:
                cause = detail_key = 'swap'
            else:
                cause = 'duplicate_new' if born[track.id] > t0 else 'duplicate_old'
                detail_key = cause
                state = 'predicted' if by_id[a].state == Track.PREDICTED else 'detected'
                detail[f'{cause}:old_{state}'] = detail.get(f'{cause}:old_{state}', 0) + 1
            windows[_window(index)]['switches'] += 1
            kind = str(kinds[g])
            c = counts.setdefault(kind, dict.fromkeys(CAUSES, 0))
            c[cause] += 1
            detail[detail_key] = detail.get(detail_key, 0) + 1
            for name in (f'gap_{_gap_name(index - t0)}',
                         f'{cause}:gap_{_gap_name(index - t0)}'):
                detail[name] = detail.get(name, 0) + 1
            if track.entity != entity:
                detail['entity_changed'] = detail.get('entity_changed', 0) + 1
    return {'bag': bag.name, 'matches': matches, 'switches': counts, 'detail': detail,
            'windows': windows, 'births_beside_predicted': births.close()}


def main(argv: list[str] | None = None) -> int:
    args, bags, params = parse_bag_args(__doc__, argv, 'id_switches')
    per_bag = run_per_bag(check_bag, bags, params, args.jobs)
    kinds = sorted({k for r in per_bag for k in r['switches']})
    total = {k: {c: sum(r['switches'].get(k, {}).get(c, 0) for r in per_bag) for c in CAUSES}
             for k in kinds}
    details = sorted({d for r in per_bag for d in r['detail']})
    windows = {}
    for name in per_bag[0]['windows'] if per_bag else ():
        switches = sum(r['windows'][name]['switches'] for r in per_bag)
        minutes = sum(r['windows'][name]['labels'] for r in per_bag) / (30 * 60)
        windows[name] = {'switches': switches, 'end_effector_minutes': round(minutes, 3),
                         'per_minute': round(switches / minutes, 2) if minutes else None}
    beside: dict[str, dict[str, int]] = {}
    for r in per_bag:
        for name, c in r['births_beside_predicted'].items():
            total_c = beside.setdefault(name, dict.fromkeys(BIRTH_OUTCOMES, 0))
            for outcome, n in c.items():
                total_c[outcome] += n
    print_json({'matches': sum(r['matches'] for r in per_bag),
                'births_beside_predicted': dict(sorted(beside.items())),
                'windows': windows,
                'switches': {c: sum(total[k][c] for k in kinds) for c in CAUSES},
                'per_kind': total,
                'detail': {d: sum(r['detail'].get(d, 0) for r in per_bag) for d in details},
                'bags': per_bag}, args.json)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
