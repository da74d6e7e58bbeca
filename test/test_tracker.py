"""The Section 5 tracker on short rendered sequences: the situations the paper describes.

Each test renders a short animation (:mod:`scenarios`, ray-cast depth only: zero-motion
prediction), runs :class:`Tracker` and, where the scenario needs it, the single-frame
estimator alone, and checks the tracker against the known tips. Parameters a test depends on
(T = ``keep_frames``, and ``max_rectify_distance`` where a prediction must stay on the
foreground) are passed explicitly, so later tuning of the defaults does not silently change
what is tested. Distances use the paper's true-positive threshold (0.15 m). Where the tracker
does not (yet) behave as the paper says, the test is a strict xfail whose reason gives the
measured outcome and the core commit it was measured on.

Situations (paper Section 5 and Fig. 7): a hand touching the torso keeps its track; clapping
hands keep two tracks; a wrong end-effector is replaced by the right one; an unmatched
end-effector is kept T frames; ids over two people; track fields; and on the synthetic
'clapping' sequence the temporal estimate beats the single-frame one.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np
import pytest
import scenarios as sc

from endeff_ros.core.floor import FloorPlane
from endeff_ros.core.graph import approximate_geodesic
from endeff_ros.core.params import EndeffParams as _EndeffParams
from endeff_ros.core.single_frame import FrameEstimate, estimate_frame
from endeff_ros.core.tracker import CASE_B_HOLD_FACTOR, Tracker, TrackerResult
from endeff_ros.core.types import Candidate, RGBDFrame, Track
from endeff_ros.scoring import MATCH_THRESHOLD_M, SequenceScorer, score_frame


def EndeffParams(**changes: object) -> _EndeffParams:  # noqa: N802 (stands in for the class)
    """The parameters with the static background off: these scenes are shots of poses held
    or changed from frame 0, which the background would take for static furniture after its
    learning time; the background has its own tests (test_background.py)."""
    return _EndeffParams(**{'background': False, **changes})

TOL = MATCH_THRESHOLD_M  # 0.15 m
HEAD, L_HAND, R_HAND, L_FOOT, R_FOOT = range(5)  # ground-truth order of scenarios.person


@dataclass
class Run:
    """Tracker results (and optionally single-frame estimates) over a list of shots."""

    shots: list[sc.Shot]
    results: list[TrackerResult]
    single: list[FrameEstimate]

    def tip(self, i: int, k: int) -> np.ndarray:
        return self.shots[i].gt[k]

    def track(self, i: int, tid: int) -> Track | None:
        return next((t for t in self.results[i].tracks if t.id == tid), None)

    def ids(self, i: int) -> list[int]:
        return [t.id for t in self.results[i].tracks]

    def nearest(self, i: int, point: np.ndarray) -> tuple[Track | None, float]:
        tracks = self.results[i].tracks
        if not tracks:
            return None, np.inf
        d = [float(np.linalg.norm(t.position - point)) for t in tracks]
        return tracks[int(np.argmin(d))], min(d)

    def dist(self, i: int, tid: int, point: np.ndarray) -> float:
        t = self.track(i, tid)
        return np.inf if t is None else float(np.linalg.norm(t.position - point))

    def sf_dist(self, i: int, point: np.ndarray) -> float:
        p = self.single[i].positions()
        return float(np.linalg.norm(p - point, axis=1).min()) if len(p) else np.inf

    def labels(self, label: str) -> list[int]:
        return [i for i, s in enumerate(self.shots) if s.label == label]

    def table(self, tid: int, k: int) -> str:
        """Per frame: label, single-frame distance to tip k, track tid's state/distance."""
        rows = []
        for i, s in enumerate(self.shots):
            t = self.track(i, tid)
            tr = 'gone' if t is None else f'st{t.state} {self.dist(i, tid, s.gt[k]):.2f}'
            sf = f'{self.sf_dist(i, s.gt[k]):.2f}' if self.single else '-'
            rows.append(f'{i}:{s.label} sf={sf} track{tid}={tr} ids={self.ids(i)}')
        return '\n'.join(rows)


def run(shots: list[sc.Shot], params: EndeffParams, *, single: bool = True) -> Run:
    tracker = Tracker(params)
    results = [tracker.update(s.frame) for s in shots]
    estimates = [estimate_frame(s.frame, params) for s in shots] if single else []
    return Run(shots, results, estimates)


# Rendering dominates the run time: each animation is rendered once per session.
touch_torso = functools.cache(sc.touch_torso)
clap = functools.cache(sc.clap)
unfold = functools.cache(sc.unfold)
hand_to_side = functools.cache(sc.hand_to_side)
star_limb_vanishes = functools.cache(sc.star_limb_vanishes)
two_people = functools.cache(sc.two_people)
still = functools.cache(sc.still)


def _runs(lost: list[int]) -> list[list[int]]:
    """Consecutive runs of frame indices."""
    out: list[list[int]] = []
    for i in lost:
        if out and out[-1][-1] == i - 1:
            out[-1].append(i)
        else:
            out.append([i])
    return out


# -- 1. A hand touching the torso keeps its track (Section 5, "a hand touched the body") ------

TOUCH_T = 8


@functools.cache
def touch_run(dropout_fill: bool = False) -> Run:
    """The hand-to-torso scene, by default without the dropout fill: with it, the procedural
    sensor's rims read again move the depth-only prediction of the hand leaving the torso
    (9 cm a frame) 0.19 m short of it, and a new id takes the hand (strict xfail below)."""
    return run(touch_torso(n_move=6, n_hold=5),
               EndeffParams(keep_frames=TOUCH_T, dropout_fill=dropout_fill))


def _touch_lost_span(r: Run) -> list[int]:
    """Frames around the contact in which the single-frame estimate has no candidate on the
    hand (the consecutive run holding the first contact frame)."""
    lost = [i for i in range(len(r.shots)) if r.sf_dist(i, r.tip(i, R_HAND)) > TOL]
    return next(span for span in _runs(lost) if r.labels('contact')[0] in span)


def test_touch_torso_single_frame_loses_the_hand():
    """The scenario: the arm attaches to the torso, the hand is no extreme, and the
    single-frame estimator alone loses it in every contact frame, for fewer than T frames."""
    r = touch_run()
    span = _touch_lost_span(r)
    assert set(r.labels('contact')) <= set(span)
    assert len(span) < TOUCH_T, span
    assert span[-1] < len(r.shots) - 2  # it shows the hand again afterwards


def test_hand_touching_torso_keeps_its_track_and_id():
    r = touch_run()
    span = _touch_lost_span(r)
    hand = [r.tip(i, R_HAND) for i in range(len(r.shots))]
    # The track nearest the hand just before the single-frame estimate lost it ...
    before = span[0] - 1
    track, d = r.nearest(before, hand[before])
    assert d < TOL
    tid = track.id
    # ... still holds the hand, with the same id, through the contact and after it.
    for i in r.labels('contact'):
        assert r.dist(i, tid, hand[i]) < TOL, r.table(tid, R_HAND)
        assert r.track(i, tid).state == Track.PREDICTED  # it lives on its prediction
    for i in range(span[-1] + 1, len(r.shots)):
        assert r.dist(i, tid, hand[i]) < TOL, r.table(tid, R_HAND)


def test_hand_touching_torso_keeps_its_id_with_the_defaults():
    """With the dropout fill the depth-only prediction of the hand leaving the torso falls
    0.19 m short of it in one frame; the track, just gone on its prediction, takes the hand's
    candidate back (``Tracker._resume_predicted``) instead of a new id taking the hand."""
    r = touch_run(dropout_fill=True)
    span = _touch_lost_span(r)
    track, _ = r.nearest(span[0] - 1, r.tip(span[0] - 1, R_HAND))
    for i in range(span[-1] + 1, len(r.shots)):
        assert r.dist(i, track.id, r.tip(i, R_HAND)) < TOL


# -- 2. Clapping hands merge, the right pair survives (Fig. 7b) ----------------------------------


@functools.cache
def clap_run() -> Run:
    return run(clap(), EndeffParams(keep_frames=5))


def _spurious(r: Run, i: int) -> np.ndarray:
    """Single-frame extremes farther than TOL from every true tip (e.g. on an elbow): the
    candidates and the far sides of loops (``loop_sides``), which a track may still match."""
    p = np.array([c.position for e in r.single[i].entities
                  for c in e.candidates + e.loop_sides]).reshape(-1, 3)
    d = np.linalg.norm(p[:, None] - r.shots[i].gt[None], axis=2).min(axis=1)
    return p[d > TOL]


def test_clap_contact_single_frame_loses_a_hand_or_adds_a_spurious_one():
    r = clap_run()
    for i in r.labels('contact'):
        hands = r.shots[i].gt[[L_HAND, R_HAND]]
        tp = score_frame(r.single[i].positions(), hands).tp
        assert tp < 2 or len(_spurious(r, i)) > 0, i


def test_clap_contact_tracker_keeps_both_hands():
    r = clap_run()
    for i in r.labels('contact'):
        hands = r.shots[i].gt[[L_HAND, R_HAND]]
        score = score_frame(r.results[i].positions(), hands)
        assert score.tp == 2, (i, [(t.id, t.state, np.round(t.position, 2).tolist())
                                   for t in r.results[i].tracks])


@pytest.mark.xfail(strict=True, reason=(
    "the candidate scorer keeps a spurious candidate at the clap's contact that the "
    'thresholds drop, and a track follows it'))
def test_clap_contact_spurious_candidate_not_tracked():
    """Fig. 7b: the merged hands give a spurious candidate (on an elbow); the memorised hand
    wins the comparison and the spurious candidate is dropped, so no track sits there."""
    r = clap_run()
    found = 0
    for i in r.labels('contact'):
        spur = _spurious(r, i)
        found += len(spur)
        pos = r.results[i].positions()
        for q in spur:
            d = np.linalg.norm(pos - q, axis=1).min()
            assert d > TOL, (i, np.round(q, 2).tolist(), f'track {d:.2f} m from it')
    assert found, 'scenario produced no spurious candidate in contact'


@pytest.mark.xfail(strict=True, reason=(
    'with the hands at 1.25 m, 0.30 m in front (as the clapping sequence) and the elbows lower, '
    'the contact leaves candidates on both forearms; the one 0.21 m from the left hand has an '
    "Eq. 7 distance of 0.957 m, longer than the hand's memorised 0.85 m, so it wins case B "
    "and the hand's track follows it (core at fbd66d8)"))
def test_clap_with_lower_elbows_tracker_keeps_both_hands():
    r = run(clap(clap=(1.25, 0.30, (-1.0, -0.4, -0.2))), EndeffParams(keep_frames=5))
    for i in r.labels('contact'):
        assert score_frame(r.results[i].positions(), r.shots[i].gt[[L_HAND, R_HAND]]).tp == 2, i


# -- 3. A wrong end-effector is dropped once the right one shows (Fig. 7c) -----------------------


def test_folded_arm_wrong_end_effector_replaced_by_hand():
    keep = 3
    r = run(unfold(), EndeffParams(keep_frames=keep))
    n = len(r.shots)
    hand = [r.tip(i, R_HAND) for i in range(n)]
    # Frame 0: the arm is folded, the single-frame extreme of that arm is the elbow, not the hand.
    assert r.sf_dist(0, hand[0]) > TOL
    wrong, d0 = r.nearest(0, hand[0])
    assert d0 > TOL
    wrong_pos = wrong.position
    # Within two frames of the arm starting to extend a track holds the hand, from then on.
    for i in range(2, n):
        _, d = r.nearest(i, hand[i])
        assert d < TOL, (i, r.table(wrong.id, R_HAND))
    # After T + 1 frames no track remains on the wrong place.
    for i in range(keep + 1, n):
        d = np.linalg.norm(r.results[i].positions() - wrong_pos, axis=1).min()
        assert d > TOL, (i, r.table(wrong.id, R_HAND))


def test_folded_arm_wrong_track_moves_to_the_hand():
    """Case B, candidate wins (Fig. 7c): the wrong track follows the hand (same id). It takes
    the hand in frame 2; the hand then moves 0.26 m in one frame while the forearm swings
    up, and with no colour the prediction stays put, more than ``max_rectify_distance`` from
    every point of frame 3: the track is dropped as having left the foreground, and the new
    track on the hand takes its id back (``revive_distance``; before young tracks gave their
    ids back too, a new id took the hand)."""
    r = run(unfold(), EndeffParams(keep_frames=3))
    wrong, _ = r.nearest(0, r.tip(0, R_HAND))
    for i in range(2, len(r.shots)):
        assert r.dist(i, wrong.id, r.tip(i, R_HAND)) < TOL, r.table(wrong.id, R_HAND)


# -- 4. An unmatched end-effector is kept T frames, then removed (case C) ------------------------


#: Far enough for a vanished star limb's prediction to snap onto the ball (0.31 m from its old
#: tip), so it stays on the foreground and is a plain case-C prediction.
REACH = 0.4


@pytest.mark.parametrize('keep', [2, 4])
def test_unmatched_limb_kept_exactly_t_frames(keep):
    """Case C: a star limb disappears, its prediction still lands on the foreground (the
    ball); the track is kept as predicted for exactly T frames, then removed."""
    shots = star_limb_vanishes(5, 7)  # detected in 5 frames >= T: T is the bound
    r = run(shots, EndeffParams(keep_frames=keep, max_rectify_distance=REACH), single=False)
    gone = r.labels('gone')[0]
    track, d = r.nearest(gone - 1, sc.star_tip(5, 0))
    assert d < TOL and track.state == Track.DETECTED
    tid = track.id
    for i in range(gone, gone + keep):
        t = r.track(i, tid)
        assert t is not None and t.state == Track.PREDICTED, (i, r.table(tid, 0))
    for i in range(gone + keep, len(shots)):
        assert r.track(i, tid) is None, (i, r.table(tid, 0))
    # The other four limbs keep their tracks throughout.
    assert all(len(r.results[i].tracks) == 4 for i in range(gone + keep, len(shots)))


@pytest.mark.parametrize('seen', [3, 4, 5])
def test_unmatched_limb_kept_no_longer_than_it_was_seen(seen):
    """Case C keeps a track at most T frames, at most as many frames as detections supported
    it, and only once confirmed (``confirm_hits``, 4): a limb seen in 4 (5) frames survives
    4 (5) unmatched frames with T = 6; one seen in 3 frames is dropped at once."""
    shots = star_limb_vanishes(seen, 9)
    params = EndeffParams(keep_frames=6, max_rectify_distance=REACH)
    assert params.confirm_hits == 4
    r = run(shots, params, single=False)
    gone = r.labels('gone')[0]
    tid = r.nearest(gone - 1, sc.star_tip(5, 0))[0].id
    kept = [i for i in range(gone, len(shots)) if r.track(i, tid) is not None]
    want = list(range(gone, gone + seen)) if seen >= params.confirm_hits else []
    assert kept == want, r.table(tid, 0)


def _nearest_candidate(entity, tip: np.ndarray) -> int:
    """Index of ``entity``'s candidate nearest ``tip``."""
    return int(np.argmin([np.linalg.norm(c.position - tip) for c in entity.candidates]))


def _with_candidates(est: FrameEstimate, candidates: list[Candidate]) -> FrameEstimate:
    """``est`` (one entity) with that entity's candidates replaced by ``candidates``."""
    return dataclasses.replace(est, entities=[dataclasses.replace(est.entities[0],
                                                                  candidates=candidates)])


@pytest.mark.parametrize('seen', [3, 5])
def test_case_b_memory_wins_no_longer_than_twice_it_was_seen(seen):
    """Case B keeps the memorised end-effector against a current candidate with a shorter
    geodesic distance (Fig. 7b), but for at most ``CASE_B_HOLD_FACTOR`` (2) times as many
    frames as detections supported the track: then the candidate wins (Fig. 7c) and the
    track follows it. Here a star limb's end is detected ``seen`` times, then the frame's
    candidate on that limb lies 0.22 m further in (the same depth image, so the prediction
    stays at the end)."""
    shot = star_limb_vanishes(1, 0)[0]
    params = EndeffParams(keep_frames=8)
    est = estimate_frame(shot.frame, params)
    ent = est.entities[0]
    tip = sc.star_tip(5, 0)
    k = _nearest_candidate(ent, tip)
    end, g = ent.candidates[k], ent.graph
    nodes = [int(np.argmin(np.linalg.norm(g.centroids - p, axis=1))) for p in end.path]
    depth = g.dist[nodes[0], nodes]
    j = int(np.argmin(np.abs(depth - 0.22)))
    inner = Candidate(position=g.centroids[nodes[j]], node=nodes[j],
                      geodesic=end.geodesic - depth[j],
                      geodesic_approx=approximate_geodesic(g.centroids[nodes[j]], g,
                                                           np.array(nodes[j:]), ent.root),
                      path=end.path[j:])
    assert inner.geodesic_approx < end.geodesic_approx  # premise: the memory is longer
    moved = _with_candidates(est, [inner if i == k else c for i, c in enumerate(ent.candidates)])
    tracker = Tracker(params)
    for _ in range(seen):
        res = tracker.update(shot.frame, estimate=est)
    tid = min(res.tracks, key=lambda t: np.linalg.norm(t.position - tip)).id
    limit = int(CASE_B_HOLD_FACTOR * seen)
    held = []
    for _ in range(limit + 4):
        t = next(t for t in tracker.update(shot.frame, estimate=moved).tracks if t.id == tid)
        held.append(t.state == Track.PREDICTED and np.linalg.norm(t.position - tip) < 0.05)
        if not held[-1]:  # the candidate won: the track is detected on it
            assert t.state == Track.DETECTED
            assert np.linalg.norm(t.position - inner.position) < 1e-9
    assert held == [True] * limit + [False] * 4


@pytest.mark.parametrize('revive', [0.3, 0.0])
def test_a_track_that_goes_on_its_prediction_takes_its_end_back(revive):
    """A star's five ends tracked for 5 frames; then every pairing of a prediction with a
    candidate is made unrelated (case A and case B off), as when the root moves or a loop
    opens: each track goes on its prediction (case C, confirmed) and each candidate is left
    over. Within ``revive_distance`` on its limb the track takes its candidate back: the same
    five ids, detected. Without (``revive_distance`` 0) each candidate starts a new track,
    under a new id (here exactly on the prediction, which goes as its duplicate)."""
    shot = star_limb_vanishes(1, 0)[0]
    params = EndeffParams(revive_distance=revive)
    est = estimate_frame(shot.frame, params)
    tracker = Tracker(params)
    for _ in range(5):
        first = tracker.update(shot.frame, estimate=est).tracks
    assert len(first) == 5
    tracker.params = dataclasses.replace(params, related_similarity=1.0, unrelated_ratio=0.0)
    for _ in range(3):
        tracks = tracker.update(shot.frame, estimate=est).tracks
        if revive:
            assert sorted(t.id for t in tracks) == sorted(t.id for t in first)
            assert all(t.state == Track.DETECTED for t in tracks)
        else:
            assert len(tracks) == 5
            assert not {t.id for t in tracks} & {t.id for t in first}


def _swap_limb_ends(case_b_path_distance: float) -> tuple[int, list[Track]]:
    """A star's limb 0 end tracked for 4 frames while the estimate leaves out limb 1's end;
    then limb 0's end leaves the estimate and limb 1's comes in (the same depth image, so
    limb 0's prediction stays at its end). ε_b is widened (``unrelated_ratio`` 3) so that the
    two ends (0.53 m apart, farther through the ball) pair in case B. Returns limb 0's track id
    and the tracks of the swapped frame."""
    shot = star_limb_vanishes(1, 0)[0]
    params = EndeffParams(unrelated_ratio=3.0, case_b_path_distance=case_b_path_distance)
    est = estimate_frame(shot.frame, params)
    ent = est.entities[0]

    def without(k: int) -> FrameEstimate:
        return _with_candidates(est, [c for i, c in enumerate(ent.candidates) if i != k])

    end0, end1 = (_nearest_candidate(ent, sc.star_tip(5, limb)) for limb in (0, 1))
    assert end0 != end1 and len(ent.candidates) == 5
    tracker = Tracker(params)
    for _ in range(4):
        res = tracker.update(shot.frame, estimate=without(end1))
    tid = min(res.tracks, key=lambda t: np.linalg.norm(t.position - sc.star_tip(5, 0))).id
    return tid, tracker.update(shot.frame, estimate=without(end0)).tracks


def test_case_b_leaves_another_limbs_end_alone():
    """Case B is one end-effector replaced by a part of its own limb (Fig. 7b: the elbow of a
    hand on the chest); an end on another limb is another end-effector. When limb 0's end
    is no longer a candidate and limb 1's end appears, limb 0's track goes on predicted at
    its end (case C) and limb 1's end starts a track of its own. Without the test
    (``case_b_path_distance`` 0) the pair is case B: limb 1's end is dropped for the
    memory, or takes limb 0's id (Fig. 7c: here it does), and no track of its own follows it."""
    tip0, tip1 = sc.star_tip(5, 0), sc.star_tip(5, 1)
    tid, tracks = _swap_limb_ends(0.2)
    kept = next(t for t in tracks if t.id == tid)
    assert kept.state == Track.PREDICTED and np.linalg.norm(kept.position - tip0) < TOL
    new = [t for t in tracks if np.linalg.norm(t.position - tip1) < TOL]
    assert len(new) == 1 and new[0].id != tid and new[0].state == Track.DETECTED
    tid, tracks = _swap_limb_ends(0.0)
    assert not any(np.linalg.norm(t.position - tip1) < TOL and t.id != tid for t in tracks)


@pytest.mark.parametrize('keep', [2, 4])
def test_unmatched_hand_predicted_at_most_t_frames(keep):
    """A hand pressed against the torso and kept there: the single-frame estimate never shows
    it again, so its track is published as predicted for at most T frames. (The pressed arm
    hangs straight: bent, it gives a candidate on the elbow 0.19-0.23 m from the hand, which
    case B would match to the track and so keep it alive.)"""
    shots = hand_to_side(7, 8)  # detected free in >= 4 frames: confirmed (confirm_hits)
    r = run(shots, EndeffParams(keep_frames=keep))
    pressed = r.labels('pressed')
    first = pressed[0]
    assert all(r.sf_dist(i, r.tip(i, R_HAND)) > TOL for i in pressed[:keep])
    track, d = r.nearest(first - 1, r.tip(first - 1, R_HAND))
    assert d < TOL
    tid = track.id
    for i in range(first, first + keep):  # kept (as a prediction, on the hand) T frames ...
        t = r.track(i, tid)
        assert t is not None and t.state == Track.PREDICTED, r.table(tid, R_HAND)
        assert r.dist(i, tid, r.tip(i, R_HAND)) < TOL
    for i in range(first + keep, len(shots)):  # ... and not longer
        assert r.track(i, tid) is None, r.table(tid, R_HAND)


@pytest.mark.parametrize('keep', [2, 4])
def test_vanished_limb_removed_within_t_frames(keep):
    """A star limb removed from the scene: its prediction has no foreground left near it, so
    it is dropped (at the latest after T predicted frames)."""
    shots = star_limb_vanishes(3, 7)
    r = run(shots, EndeffParams(keep_frames=keep), single=False)
    gone = r.labels('gone')[0]
    tip = sc.star_tip(5, 0)
    track, d = r.nearest(gone - 1, tip)
    assert d < TOL
    tid = track.id
    predicted = [i for i in range(gone, len(shots)) if r.track(i, tid) is not None]
    assert all(r.track(i, tid).state == Track.PREDICTED for i in predicted)
    assert len(predicted) <= keep
    for i in range(gone + keep, len(shots)):
        assert r.track(i, tid) is None
        assert np.linalg.norm(r.results[i].positions() - tip, axis=1).min() > TOL


def _limb_away(n_gone: int) -> list[sc.Shot]:
    """A star whose limb 0 is gone for ``n_gone`` frames and then comes back."""
    whole = sc.star_limb_vanishes(6, n_gone)
    back = [sc.shoot(sc.scenes.star(5, length=sc.STAR_LENGTH), len(whole) + i, label='back')
            for i in range(4)]
    return whole + back


@pytest.mark.parametrize(('n_gone', 'revive', 'same'), [(3, 0.3, True), (10, 0.3, False),
                                                         (3, 0.0, False)])
def test_end_effector_found_again_soon_takes_its_id_back(n_gone, revive, same):
    """A limb gone for a few frames (its track dropped: no foreground left near its
    prediction) and back where it was: within ``revive_frames`` of the loss, the new track
    takes the lost id back (``revive_distance``); later, or with revival off, it gets a new
    id, never one used before."""
    shots = _limb_away(n_gone)
    r = run(shots, EndeffParams(keep_frames=8, revive_frames=8, revive_distance=revive),
            single=False)
    tip = sc.star_tip(5, 0)
    gone, back = r.labels('gone'), r.labels('back')
    before, d = r.nearest(gone[0] - 1, tip)
    assert d < TOL
    assert all(r.track(i, before.id) is None for i in gone[2:]), r.table(before.id, 0)
    after, d = r.nearest(back[-1], tip)
    assert d < TOL
    assert (after.id == before.id) is same, (before.id, after.id)
    if not same:
        assert after.id > max(t.id for i in range(back[0]) for t in r.results[i].tracks)
    # The other limbs keep their ids throughout.
    others = {r.nearest(0, sc.star_tip(5, k))[0].id for k in range(1, 5)}
    assert all(others <= set(r.ids(i)) for i in range(6, len(shots)))


def _limb_flickers() -> list[sc.Shot]:
    """A star whose limb 0 shows for two frames only, is gone for three and comes back."""
    def star(i: int, label: str, limb: bool) -> sc.Shot:
        keep = None if limb else (1, 2, 3, 4)
        return sc.shoot(sc.scenes.star(5, keep=keep, length=sc.STAR_LENGTH), i, label=label)

    plan = [('without', False)] * 6 + [('blip', True)] * 2 + [('gone', False)] * 3
    plan += [('back', True)] * 4
    return [star(i, label, limb) for i, (label, limb) in enumerate(plan)]


@pytest.mark.parametrize(('revive', 'same'), [(0.3, True), (0.0, False)])
def test_an_end_seen_too_briefly_to_be_kept_takes_its_id_back_too(revive, same):
    """An end that is an extreme in a frame or two at a time (a hand that flickers in and
    out of the extremes) gets a track each time, too young to be kept alive when it goes
    (``confirm_hits``); found again within T frames where it was, it takes that id back as
    a confirmed track's end does, instead of a new id each time."""
    shots = _limb_flickers()
    r = run(shots, EndeffParams(keep_frames=8, revive_distance=revive), single=False)
    tip = sc.star_tip(5, 0)
    blip, gone, back = r.labels('blip'), r.labels('gone'), r.labels('back')
    first, d = r.nearest(blip[-1], tip)
    assert d < TOL
    assert all(r.track(i, first.id) is None for i in gone), r.table(first.id, 0)
    again, d = r.nearest(back[-1], tip)
    assert d < TOL
    assert (again.id == first.id) is same, (first.id, again.id)


# -- 5. Two people: unique ids, entity per person ------------------------------------------------


def test_two_people_unique_ids_and_entities():
    r = run(two_people(4), EndeffParams(keep_frames=5), single=False)
    for i, res in enumerate(r.results):
        ids = r.ids(i)
        assert len(ids) == len(set(ids)), ids
        tips = r.shots[i].gt
        entity_of = []
        for person in (range(0, 5), range(5, 10)):
            ents = set()
            for k in person:
                t, d = r.nearest(i, tips[k])
                if d < TOL:
                    ents.add(t.entity)
            assert len(ents) == 1, (i, ents)
            entity_of.append(ents.pop())
        assert entity_of[0] != entity_of[1]
        if i >= 1:  # every tip of both people is held by a track (one-to-one)
            assert score_frame(res.positions(), tips).tp == 10, i
    all_ids = [tid for i in range(len(r.results)) for tid in r.ids(i)]
    assert len(set(all_ids)) >= 10


# -- 6. Track fields, reset, parameters at run time ----------------------------------------------


def test_still_person_keeps_every_id():
    """A person standing still: one track per end-effector, same ids in every frame."""
    r = run(still(), EndeffParams(keep_frames=5), single=False)
    first = {k: r.nearest(0, r.tip(0, k))[0].id for k in range(5)}
    for i in range(1, len(r.shots)):
        for k in (L_HAND, R_HAND, L_FOOT, R_FOOT):
            t, d = r.nearest(i, r.tip(i, k))
            assert d < TOL and t.id == first[k], (i, k, first, r.ids(i))


def test_tracks_publish_the_part_centre():
    """A detected track is published where its candidate's part centre is (a hand inside its
    palm), although the tracker follows the rounded end (``Candidate.end_centre``)."""
    r = run(still(), EndeffParams(keep_frames=5), single=False)
    shifted = 0
    for res in r.results:
        cands = [c for e in res.estimate.entities for c in e.candidates]
        centres = np.array([c.position for c in cands]).reshape(-1, 3)
        for t in res.tracks:
            if t.state == Track.DETECTED:
                assert np.linalg.norm(centres - t.position, axis=1).min() < 1e-9
        shifted += sum(np.linalg.norm(c.centre_shift) > 0.01 for c in cands)
    assert shifted  # premise: some parts are long (the hands)


def test_track_state_age_confidence():
    """The paper's memory weight as confidence (``scored_confidence`` off)."""
    keep = 4
    r = run(star_limb_vanishes(5, 7), EndeffParams(keep_frames=keep, max_rectify_distance=REACH,
                                                   scored_confidence=False), single=False)
    people = run(hand_to_side(5, 8), EndeffParams(keep_frames=keep, scored_confidence=False),
                 single=False)
    for rr in (r, people):
        for i, res in enumerate(rr.results):
            for t in res.tracks:
                assert t.state in (Track.DETECTED, Track.PREDICTED)
                assert 0.0 <= t.confidence <= 1.0
                prev = rr.track(i - 1, t.id) if i else None
                assert t.age == (1 if prev is None else prev.age + 1), (i, t.id)  # +1 a frame
        detected = [t.confidence for res in rr.results for t in res.tracks if t.state == 0]
        predicted = [t.confidence for res in rr.results for t in res.tracks if t.state == 1]
        assert predicted and np.mean(predicted) < np.mean(detected)
    # The vanished limb: detected, then predicted with a confidence below the detected one that
    # falls with every further unmatched frame.
    gone = r.labels('gone')[0]
    tid = r.nearest(gone - 1, sc.star_tip(5, 0))[0].id
    assert r.track(gone - 1, tid).state == Track.DETECTED
    confs = [r.track(i, tid).confidence for i in range(gone - 1, gone + keep)]
    assert all(b < a for a, b in zip(confs, confs[1:])), confs


@pytest.mark.parametrize('forget_ids', [False, True])
def test_reset_clears_tracks(forget_ids):
    shots = star_limb_vanishes(3, 7)
    tracker = Tracker(EndeffParams(keep_frames=4))
    for s in shots[:3]:
        used = {t.id for t in tracker.update(s.frame).tracks}
    tracker.reset(forget_ids=forget_ids)
    again = tracker.update(shots[3].frame)
    fresh = Tracker(EndeffParams(keep_frames=4)).update(shots[3].frame)
    assert [t.id for t in fresh.tracks] == [0, 1, 2, 3]
    if forget_ids:
        assert [t.id for t in again.tracks] == [0, 1, 2, 3]
    else:  # ids are never reused after a reset
        assert len(again.tracks) == 4 and not used & {t.id for t in again.tracks}
    assert all(t.age == 1 and t.state == Track.DETECTED for t in again.tracks)
    np.testing.assert_allclose(again.positions(), fresh.positions())


def test_params_change_between_frames_takes_effect():
    shots = star_limb_vanishes(4, 7)  # limb 0 seen in 4 frames (confirmed), gone from 4 on
    tip = sc.star_tip(5, 0)
    tracker = Tracker(EndeffParams(keep_frames=4, max_rectify_distance=REACH))
    results = [tracker.update(s.frame) for s in shots[:6]]  # limb predicted in frames 4, 5
    tid = min(results[3].tracks, key=lambda t: np.linalg.norm(t.position - tip)).id
    assert any(t.id == tid and t.state == Track.PREDICTED for t in results[5].tracks)
    tracker.params = tracker.params.replace(keep_frames=1)
    assert all(t.id != tid for t in tracker.update(shots[6].frame).tracks)
    # The other way: a longer T keeps a prediction that the old T would have dropped ...
    tracker = Tracker(EndeffParams(keep_frames=1, max_rectify_distance=REACH))
    results = [tracker.update(s.frame) for s in shots[:5]]  # limb predicted in frame 4
    tracker.params = tracker.params.replace(keep_frames=3)
    nxt = tracker.update(shots[5].frame)
    assert any(t.id == tid and t.state == Track.PREDICTED for t in nxt.tracks)
    # ... and with a short rectification reach the limb's first prediction has left the
    # foreground: dropped at once.
    tracker = Tracker(EndeffParams(keep_frames=4, max_rectify_distance=REACH))
    for s in shots[:4]:
        tracker.update(s.frame)
    tracker.params = tracker.params.replace(max_rectify_distance=0.15)
    assert all(t.id != tid for t in tracker.update(shots[4].frame).tracks)


def _rendered(name: str, *, quick: bool = False):
    """(RGB-D frame, ground truth) of a synthetic sequence; frames whose depth image the
    sequence drops are no RGB-D frames and are skipped."""
    from endeff_ros.synth import render_sequence

    for f in render_sequence(name, quick=quick):
        if f.depth is not None:
            yield RGBDFrame(f.stamp_ns, f.frame_id, f.depth, f.intrinsics, f.color), f.gt


# -- 7. The synthetic 'clapping' sequence: temporal recall above single-frame recall ------------


@pytest.mark.integration
def test_clapping_sequence_temporal_recall_beats_single_frame():
    params = EndeffParams(keep_frames=5)
    tracker = Tracker(params)
    scorers = {'temporal': SequenceScorer(), 'single_frame': SequenceScorer()}
    frames = 0
    for frame, gt in _rendered('clapping'):
        frames += 1
        res = tracker.update(frame)
        scorers['temporal'].add(res.positions(), gt)
        scorers['single_frame'].add(estimate_frame(frame, params).positions(), gt)
    assert frames >= 70
    temporal = scorers['temporal'].result()
    single = scorers['single_frame'].result()
    assert temporal.recall > single.recall, (temporal, single)


def test_punching_fists_on_the_chest_keep_their_tracks():
    """Between punches the fists rest on the chest: no extremum (the elbows are). A predicted
    fist keeps the distance of its arm (Eq. 7 through the mid-band of its last detected path,
    Section 5.2), and the memory of that distance fades slowly (σ = 0.99, Eq. 9), so its
    track holds the fist in at least 55 % of the frames in which the single-frame estimate
    misses it (measured 65 %; 42 % with σ = 0.9; 25 % with σ = 0.9 and Eq. 7 through the
    current graph, which puts the fist at the chest's distance and lets the elbow win
    case B)."""
    params = EndeffParams()
    tracker = Tracker(params)
    missed = held = 0
    for frame, gt in _rendered('punching'):
        tracked = tracker.update(frame).positions()
        single = estimate_frame(frame, params).positions()
        for fist in np.asarray(gt)[1:3]:  # ground truth 1, 2: the hands
            if len(single) and np.linalg.norm(single - fist, axis=1).min() < TOL:
                continue
            missed += 1
            held += bool(len(tracked)) and np.linalg.norm(tracked - fist, axis=1).min() < TOL
    assert missed >= 60  # premise: the guard hides the fists from the single frame
    assert held >= 0.55 * missed, (held, missed)


@pytest.mark.xfail(strict=True, reason=(
    'FPR 0.081 with the candidate scorer (below 0.08 with the thresholds alone): it keeps an '
    'end on the legs in some frames'))
def test_bending_hand_predictions_do_not_slip_onto_the_legs():
    """The bending person's hands hang in front of the shins; DIS moves them too little, and
    a prediction whose window then reads the legs behind would be carried onto the legs and
    stay there as a false positive. Scene flow drops such a step (``propagate_points``: a
    depth change of more than the tolerance away from the camera is a lost surface), so the
    sequence's temporal FPR stays below 0.08 (measured 0.051; 0.122 without that rule)."""
    tracker = Tracker(EndeffParams())
    scorer = SequenceScorer()
    for frame, gt in _rendered('bending'):
        scorer.add(tracker.update(frame).positions(), gt)
    result = scorer.result()
    assert result.recall > 0.9, result
    assert result.fpr < 0.08, result


def test_update_with_early_estimate_and_flow_equals_update():
    """What the node runs early (``Tracker.estimate`` on the depth, ``Tracker.flow`` on the
    colour image) passed to ``update`` gives exactly what ``update`` alone gives."""
    whole, split = Tracker(EndeffParams()), Tracker(EndeffParams())
    frames = [frame for frame, _ in _rendered('waving_one_hand', quick=True)]
    used_flow = 0
    for i, frame in enumerate(frames):
        a = whole.update(frame)
        estimate = split.estimate(frame) if i % 3 != 1 else None
        flow = split.flow(frame.color, frame.intrinsics) if i % 3 != 2 else None
        used_flow += flow is not None
        b = split.update(frame, estimate=estimate, flow=flow)
        assert [t.id for t in a.tracks] == [t.id for t in b.tracks], i
        np.testing.assert_array_equal(a.positions(), b.positions())
        assert [t.state for t in a.tracks] == [t.state for t in b.tracks]
    assert used_flow >= 4  # premise: the early flow was exercised


# -- Warm-up (the node runs it before subscribing) -----------------------------------------------


def test_warm_up_runs_every_stage_and_leaves_no_state():
    from endeff_ros.core.warmup import warm_up, warm_up_frames

    first, second = warm_up_frames()
    probe = Tracker(EndeffParams())
    assert len(probe.update(first).tracks) == 4  # the star's four limbs
    assert probe.flow(second.color, second.intrinsics) is not None  # the predict path runs

    shots = sc.clap()[:4]
    frames = [s.frame for s in shots]
    warmed = Tracker(EndeffParams())
    assert warm_up(warmed) == 4
    fresh = Tracker(EndeffParams())
    for frame in frames:
        a, b = warmed.update(frame), fresh.update(frame)
        assert [(t.id, t.state) for t in a.tracks] == [(t.id, t.state) for t in b.tracks]
        np.testing.assert_allclose(a.positions(), b.positions())


def test_the_floor_is_fitted_anew_when_the_camera_moves():
    """After a camera motion (the background re-learnt) the tracker fits the floor again
    instead of passing on the plane of the old view (a tilt of the head changes it by more
    than following the floor can catch up with)."""
    LEVEL = sc.scenes.LEVEL
    depth = sc.scenes.shoot(sc.scenes.person('arms_down', x=0.2), LEVEL).frame.depth
    tracker = Tracker(_EndeffParams(box_max_z=4.3))

    def step(k: int) -> FrameEstimate:
        frame = RGBDFrame(k * 33_333_333, 'camera', depth, LEVEL.intrinsics)
        return tracker.update(frame).estimate

    step(0)
    stale = FloorPlane(np.array([0.0, -0.9, -np.sqrt(1 - 0.81)]), 1.0)  # 26 degrees off
    tracker._floor = stale  # as if the floor had been fitted in another view
    step(1)
    assert step(2).floor.normal @ stale.normal == pytest.approx(stale.normal @ stale.normal)
    tracker.background.relearns += 1  # the camera moved
    step(3)
    assert step(4).floor.normal @ np.array([0.0, -1.0, 0.0]) > 0.999  # the level floor
    tracker._floor = stale
    tracker.reset_background()  # the ~/reset_background service: the same
    assert step(5).floor.normal @ np.array([0.0, -1.0, 0.0]) > 0.999


def _folded_arms_worst_track(params: EndeffParams) -> float:
    """Arms folded from the first frame, 8 frames: the distance from the last frame's
    farthest track to its nearest labelled end."""
    shots = [sc.shoot(sc.person(sc.ARM_FOLDED), i) for i in range(8)]
    result = run(shots, params, single=False).results[-1]
    return max(float(np.linalg.norm(shots[-1].gt - t.position, axis=1).min())
               for t in result.tracks)


def test_no_track_starts_on_the_far_side_of_a_loop():
    """Arms folded from the first frame: the elbows on the far side of the loop the arms
    close are no end-effectors (``loop_far_sides``) and start no track; without the rule each
    frame's elbow candidate became a track 0.28 m from every labelled end."""
    # Without the dropout fill: the procedural sensor's dropped rims (neck, shoulders) read
    # again change where this scene's loop closes (below).
    base = EndeffParams(dropout_fill=False)
    assert _folded_arms_worst_track(base.replace(loop_far_sides=False)) > 0.2  # premise
    assert _folded_arms_worst_track(base) < TOL


@pytest.mark.xfail(strict=True, reason=(
    'with the dropout fill, one elbow of the folded arms is an extreme of the graph, not the '
    'far side of a loop, and starts a track'))
def test_no_track_starts_on_the_far_side_of_a_loop_with_the_defaults():
    assert _folded_arms_worst_track(EndeffParams()) < TOL
