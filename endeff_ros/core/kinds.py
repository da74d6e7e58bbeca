"""Which part of a person each published end-effector is: head, hand, foot, or other.

A subscriber (a human-robot interaction node) first asks "which of these is the person's
hand?"; the estimator finds ends of kinematic chains and knows nothing of bodies. This module
answers from geometry the estimator already has, with no body model, so that any articulated
entity gets an answer, and for one that is not person-like the answer is 0 (other):

- **Up and the floor**: the floor plane the estimator fits (Section 3) gives the up direction
  and each end's height above the floor; without a floor (none in view yet) the last floor
  seen, else the camera's up axis (-y) and heights above the entity's lowest point.
- **Is the entity person-like?** A standing, walking or seated person is tall (its points
  span at least :data:`PERSON_MIN_SPAN` m up), rests on the floor (its lowest points within
  :data:`FLOOR_CONTACT` m of it) and shows at least :data:`MIN_PERSON_ENDS` ends. A person
  close to the camera is partly in the image: cut by its lower border, it is person-like
  with two ends, one of them head-like (below); cut by its upper border, with one or two
  ends on the floor and none else there. A chair (0.96 m), a robot arm on its pedestal
  (one or two ends) or a star held in the air (resting on nothing) fail these tests.
- **Feet** are the ends near the floor: below :data:`FOOT_HEIGHT` m, or in the lowest
  :data:`FOOT_FRACTION` of the entity's span, and below its root (for a body cut by the
  image's lower border, only ends by a known floor).
- **The head** is the end that goes most directly up from the root: of the ends rising
  :data:`HEAD_MIN_RISE` to :data:`HEAD_MAX_RISE` m above it whose geodesic length exceeds
  their rise by at most :data:`HEAD_MAX_DETOUR`, the one with the smallest excess. A head
  sits straight above the trunk; a hand raised as high has come up the arm (it rises more and
  its path is longer); one in front of the chest rises little for its length. On a body cut
  by the image's lower border the rise has no upper bound: its root may lie at the thighs.
  At most one per entity, and none when no end qualifies (a head hidden behind a raised arm).
- **Hands** are the other ends of a person-like entity.
- **History**: a track's kind is the one with the most votes over its recent frames (each
  frame's vote decays by :data:`VOTE_DECAY`), so a foot raised for a kick, a head lost behind a
  raised arm or legs that leave the image for a few frames do not flip the kind; an entity
  that fails the person tests in a frame votes 0 for its ends, unless enough of its ends'
  votes so far were for a part of a person (:data:`PERSON_MEMORY`: a person who sits down
  on the floor or bends over stays a person).

Failure modes (documented in docs/output.md): a person lying down or crawling is not tall
(its ends are 0, unless it stood before; then hands on the floor are feet); a cartwheel or a
handstand puts the feet above the root (they become hands); a foot raised for long (a kick
held, a foot on a chair) becomes a hand once its votes are outweighed; two people touching
are one entity (one head between them); a person that a table or furniture cuts in the
middle rests on nothing in view and keeps the kinds its ends had (new ends are 0); furniture
taller than :data:`PERSON_MIN_SPAN` that moves (so the background does not take it) and shows
three ends is a person.

Pure numpy: no ROS import (the core's rule).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from .types import Track

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy.typing as npt

    from .floor import FloorPlane
    from .single_frame import FrameEstimate
    from .types import Intrinsics

#: Kinds in ``Track.kind`` order: index = value.
KIND_NAMES = ('other', 'head', 'hand', 'foot')

#: An entity whose points span this much up (m) or more is tall enough for a standing or
#: seated person, whatever rests on the floor (a seated person's chair legs join the feet):
#: a chair's backrest tops at 0.96 m; a seated adult's head is 1.2 m and more up.
PERSON_MIN_SPAN = 1.1
#: A lower entity, down to this span (m), is person-like only with at most
#: :data:`MAX_FLOOR_ENDS` ends on the floor: a person bending, crouching, kneeling or
#: getting up; a chair shows its four legs. On the dev split of the quick mocap suite, 0.5
#: rather than 1.1 (no low person) left a person's end 0 in 122 cases instead of 231 of
#: 1,089 (offline replay of the rules, 2026-11-28).
PERSON_LOW_SPAN = 0.5
#: A person rests on the floor: the entity's lowest points (1st percentile) lie within this
#: many metres of it. A star or a drone in the air does not.
FLOOR_CONTACT = 0.3
#: At most this many ends of a person lie near the floor (its feet); a chair has four.
MAX_FLOOR_ENDS = 2
#: A person-like entity shows at least this many ends: a robot arm on its pedestal shows two
#: (the gripper and the pedestal's foot), and with 2 here the paper suite's robot arm became
#: a person in every frame.
MIN_PERSON_ENDS = 3
#: An entity whose lowest image rows come within this fraction of the image's height of its
#: lower border is cut there: a person close to the camera, seen from the waist or the
#: knees up, who rests on nothing in view. Such an entity is person-like when it spans at
#: least :data:`CUT_MIN_SPAN` m up and shows :data:`CUT_MIN_ENDS` ends, one of them
#: head-like. Cut by the upper border (the head out of view), it is person-like with one or
#: two ends on the floor and at least :data:`CUT_MIN_ENDS` ends.
CUT_BORDER = 0.08
CUT_MIN_SPAN = 0.5
CUT_MIN_ENDS = 2
#: An entity that fails the tests in a frame is still person-like when its ends were (their
#: votes' share of head, hand and foot is above this on average): a person who sits down on
#: the floor, bends to pick something up or lies down after standing in view. An entity
#: that never passed them has no such votes. On the quick mocap suite's dev split, 0.3
#: rather than 0.5 left 64 rather than 122 of 1,089 matched ends of people 0 (offline replay
#: of the rules, 2026-11-28).
PERSON_MEMORY = 0.3
#: An end this high (m) above the floor or lower is a foot (a foot's centre is 5-15 cm up; a
#: hand hanging at the side of a standing adult is 0.7 m up).
FOOT_HEIGHT = 0.35
#: ... as is one in the lowest part of the entity's span (a fraction of it, below the root),
#: which holds for a short person, a child or a camera that sees the floor badly.
FOOT_FRACTION = 0.3
#: The head rises at least this much (m) above the root (a standing adult's root is at the
#: belly, the head's centre about 0.6 m higher).
HEAD_MIN_RISE = 0.2
#: ... and at most this much: a hand raised above the head rises more. Matched heads of the
#: quick mocap suite's dev split rise 0.62-0.79 m (quartiles), raised hands up to 0.9 m and
#: more; 1.0 against 0.8 kept 0.57 rather than 0.49 of the heads (offline replay).
HEAD_MAX_RISE = 1.0
#: A head's geodesic length exceeds its rise by at most this (m; 0.39 at the dev split's 3rd
#: quartile): it sits straight above the trunk. A hand in front of the chest has come up to
#: the shoulder and back down the arm (1.0 m median excess).
HEAD_MAX_DETOUR = 0.5
#: Each frame's vote for a track's kind is weighted down by this factor per later frame
#: (half its weight after about 7 frames, a quarter of a second at 30 Hz).
VOTE_DECAY = 0.9
#: Votes are forgotten for tracks absent this many frames (ids are not reused, but a lost
#: track gives its id back when found again within ``keep_frames``).
FORGET_FRAMES = 90

_CAMERA_UP = np.array([0.0, -1.0, 0.0])


class EntityShape(NamedTuple):
    """What the person test needs of one entity: its root's height, the 1st and 99th
    percentiles of its points' heights (m, above the floor where ``on_floor``, else along
    the up direction from an arbitrary origin), and whether the image's lower border cuts it
    (``cut``: its lowest points in the image lie within :data:`CUT_BORDER` of the border),
    or the upper border (``cut_top``: a person close to the camera whose head is out of it)."""

    root_height: float
    bottom: float
    top: float
    on_floor: bool
    cut: bool = False
    cut_top: bool = False


def entity_shapes(estimate: FrameEstimate, up: npt.NDArray[np.float64],
                  offset: float | None,
                  intrinsics: Intrinsics | None = None) -> dict[int, EntityShape]:
    """Per entity index of ``estimate``: its :class:`EntityShape`, heights ``p . up +
    offset`` (``offset`` None: no floor known, heights along ``up`` from the origin);
    ``intrinsics`` tell whether the image's lower border cuts it (without them, never)."""
    out: dict[int, EntityShape] = {}
    for ent in estimate.entities:
        if len(ent.point_index) == 0:
            continue
        pts = estimate.points[ent.point_index]
        h = pts @ up + (offset or 0.0)
        bottom, top = np.percentile(h, [1.0, 99.0])
        cut = cut_top = False
        if intrinsics is not None:
            z = np.maximum(pts[:, 2], 1e-6)
            v = intrinsics.fy * pts[:, 1] / z + intrinsics.cy
            cut = bool(v.max() >= (1.0 - CUT_BORDER) * intrinsics.height)
            cut_top = bool(v.min() <= CUT_BORDER * intrinsics.height)
        out[ent.entity] = EntityShape(float(ent.root @ up + (offset or 0.0)), float(bottom),
                                      float(top), offset is not None, cut, cut_top)
    return out


def frame_kinds(positions: npt.NDArray[np.float64], geodesics: npt.NDArray[np.float64],
                entities: npt.NDArray[np.intp], shapes: dict[int, EntityShape],
                up: npt.NDArray[np.float64], offset: float | None,
                prior: npt.NDArray[np.float64] | None = None) -> npt.NDArray[np.intp]:
    """One frame's kind (``Track.KIND_*``) per end: (M, 3) positions, (M,) geodesic lengths
    to the root and entity indices; -1 where the frame says nothing (an end without a known
    entity). ``prior`` (M,): each end's share of person votes so far (:data:`PERSON_MEMORY`).
    The rules are the module's."""
    m = len(positions)
    kinds = np.full(m, -1, dtype=np.intp)
    if m == 0:
        return kinds
    prior = np.zeros(m) if prior is None else np.asarray(prior, dtype=np.float64)
    heights = positions @ up + (offset or 0.0)
    for e in np.unique(entities):
        shape = shapes.get(int(e))
        if shape is None:
            continue
        mine = np.flatnonzero(entities == e)
        kinds[mine] = Track.KIND_OTHER
        h = heights[mine]
        span = shape.top - shape.bottom
        floor_level = 0.0 if shape.on_floor else shape.bottom
        rise = h - shape.root_height
        if shape.cut:  # the legs are out of the image: only an end by the floor is a foot
            low = shape.on_floor & (h < FOOT_HEIGHT)
        else:
            low = (h - floor_level < FOOT_HEIGHT) | (h - shape.bottom < FOOT_FRACTION * span)
        low &= rise < 0
        grounded = not shape.on_floor or shape.bottom < FLOOR_CONTACT
        floor_ends = np.count_nonzero(low)
        geo = geodesics[mine]
        # Standing or seated (on a chair, whose legs then join the person's feet).
        standing = (len(mine) >= MIN_PERSON_ENDS and grounded and (
            span >= PERSON_MIN_SPAN
            or (span >= PERSON_LOW_SPAN and floor_ends <= MAX_FLOOR_ENDS)))
        # Partly in the image: the upper body above a lower border that cuts it, or the
        # legs below an upper border that cuts the head off.
        partial = span >= CUT_MIN_SPAN and len(mine) >= CUT_MIN_ENDS and (
            (shape.cut and bool(_head_like(rise, geo, cut=True).any()))
            or (shape.cut_top and grounded and 0 < floor_ends <= MAX_FLOOR_ENDS))
        if not (standing or partial or prior[mine].mean() > PERSON_MEMORY):
            continue
        kinds[mine] = np.where(low, Track.KIND_FOOT, Track.KIND_HAND)
        upper = np.flatnonzero(~low & _head_like(rise, geo, cut=shape.cut))
        if upper.size:
            kinds[mine[upper[np.argmin(geo[upper] - rise[upper])]]] = Track.KIND_HEAD
    return kinds


def may_be_person(kind: int, shape: EntityShape | None) -> bool:
    """Whether an end of ``kind`` on an entity of ``shape`` may belong to a person, for the
    static background, which keeps the entities of the start that may be people
    (``background_keep_initial``): an end of a person-like entity (``kind`` not 0), or any end
    of an entity lower than :data:`PERSON_LOW_SPAN` (a person lying on the floor or crawling
    fails the person tests, and nothing tells it from a low box: people win), or of one whose
    shape is not known. What is left is furniture by the tests: at least
    :data:`PERSON_LOW_SPAN` tall, with four legs on the floor, or fewer than
    :data:`MIN_PERSON_ENDS` ends."""
    if kind != Track.KIND_OTHER or shape is None:
        return True
    return shape.top - shape.bottom < PERSON_LOW_SPAN


def person_candidates(estimate: FrameEstimate, intrinsics: Intrinsics | None = None,
                      labeller: KindLabeller | None = None) -> npt.NDArray[np.bool_]:
    """Per candidate of ``estimate`` (in :meth:`FrameEstimate.positions` order): whether it
    may belong to a person (:func:`may_be_person`) by this frame alone, for a caller without
    tracks (the single-frame estimator); ``labeller`` keeps the last floor seen."""
    labeller = labeller or KindLabeller()
    shapes = labeller.shapes(estimate, intrinsics)
    entities = [e.entity for e in estimate.entities for _ in e.candidates]
    return np.array([may_be_person(max(int(k), 0), shapes.get(e)) for k, e in
                     zip(labeller.candidate_kinds(estimate, intrinsics, approx=False),
                         entities)], dtype=bool)


def _head_like(rise: npt.NDArray[np.float64], geodesic: npt.NDArray[np.float64], *,
               cut: bool = False) -> npt.NDArray[np.bool_]:
    """Ends that may be a head: between :data:`HEAD_MIN_RISE` and :data:`HEAD_MAX_RISE`
    above the root, and reached from it almost straight up (geodesic length less rise at most
    :data:`HEAD_MAX_DETOUR`). On an entity the image's lower border cuts (``cut``) the root
    is found wherever the cut body's graph puts it, down to the thighs, so the rise has no
    upper bound there."""
    top = np.inf if cut else HEAD_MAX_RISE
    return (rise >= HEAD_MIN_RISE) & (rise <= top) & (geodesic - rise <= HEAD_MAX_DETOUR)


@dataclass
class _Votes:
    score: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(len(KIND_NAMES)))
    last: int = 0
    age: int = 0


@dataclass
class KindLabeller:
    """Kinds of a tracker's published tracks, with each track's vote history: kept on the
    tracker, one call per frame (:meth:`label`)."""

    decay: float = VOTE_DECAY
    _votes: dict[int, _Votes] = field(default_factory=dict)
    _frame: int = 0
    _up: npt.NDArray[np.float64] = field(default_factory=lambda: _CAMERA_UP.copy())
    _offset: float | None = None
    _shapes: dict[int, EntityShape] = field(default_factory=dict)
    _shapes_of: tuple[FrameEstimate, Intrinsics | None] | None = field(default=None,
                                                                        repr=False)

    def shapes(self, estimate: FrameEstimate,
               intrinsics: Intrinsics | None = None) -> dict[int, EntityShape]:
        """The :class:`EntityShape` of each entity of ``estimate``, after taking its floor
        (:meth:`see_floor`); computed once per estimate, since the tracker asks for the kinds
        of its new ends (:meth:`candidate_kinds`) and then labels its tracks in one frame."""
        last = self._shapes_of
        if last is None or last[0] is not estimate or last[1] is not intrinsics:
            self.see_floor(estimate.floor)
            self._shapes = entity_shapes(estimate, self._up, self._offset, intrinsics)
            self._shapes_of = (estimate, intrinsics)
        return self._shapes

    def label(self, tracks: Sequence[Track], estimate: FrameEstimate,
              intrinsics: Intrinsics | None = None) -> list[Track]:
        """``tracks`` with ``kind`` set, from ``estimate``'s floor and entities (and the
        image's size and projection, ``intrinsics``, which tell an entity cut by the image's
        lower border)."""
        return self.label_shapes(tracks, self.shapes(estimate, intrinsics))

    def candidate_kinds(self, estimate: FrameEstimate, intrinsics: Intrinsics | None = None,
                        *, approx: bool = True) -> npt.NDArray[np.intp]:
        """The kind this frame alone gives each candidate of ``estimate`` (in
        :meth:`FrameEstimate.positions` order; no vote history; -1: none), from their Eq. 7
        geodesic distances (``approx``: the ones tracks carry and the rules were chosen on)
        or their Eq. 6 ones (the single-frame estimator's marks, :func:`person_candidates`)."""
        rows = [(c.position, c.geodesic_approx if approx else c.geodesic, e.entity)
                for e in estimate.entities for c in e.candidates]
        if not rows:
            return np.zeros(0, dtype=np.intp)
        shapes = self.shapes(estimate, intrinsics)
        return frame_kinds(np.array([r[0] for r in rows], dtype=np.float64),
                           np.array([r[1] for r in rows], dtype=np.float64),
                           np.array([r[2] for r in rows], dtype=np.intp), shapes,
                           self._up, self._offset)

    def label_shapes(self, tracks: Sequence[Track],
                     shapes: dict[int, EntityShape]) -> list[Track]:
        """:meth:`label` from the entities' shapes (:func:`entity_shapes`, with this
        labeller's up and floor): the offline tools' entry."""
        self._frame += 1
        positions = np.array([t.position for t in tracks], dtype=np.float64).reshape(-1, 3)
        history = []
        for t in tracks:
            v = self._votes.get(t.id)
            if v is None or t.age <= v.age:  # a new track, or an id given out again
                v = self._votes[t.id] = _Votes()
            v.score *= self.decay ** (self._frame - v.last) if v.last else 1.0
            v.last, v.age = self._frame, t.age
            history.append(v)
        prior = np.array([v.score[1:].sum() / v.score.sum() if v.score.sum() > 0 else 0.0
                          for v in history])
        votes = frame_kinds(positions, np.array([t.geodesic for t in tracks], dtype=np.float64),
                            np.array([t.entity for t in tracks], dtype=np.intp), shapes,
                            self._up, self._offset, prior)
        out = []
        for t, vote, v in zip(tracks, votes, history):
            if vote >= 0:
                v.score[vote] += 1.0
            out.append(replace(t, kind=int(np.argmax(v.score))))
        if self._frame % FORGET_FRAMES == 0:
            self._votes = {i: v for i, v in self._votes.items()
                           if self._frame - v.last <= FORGET_FRAMES}
        return out

    def may_be_people(self, tracks: Sequence[Track]) -> list[bool]:
        """Per track labelled by the last :meth:`label` call: whether its entity may be a
        person (:func:`may_be_person`)."""
        return [may_be_person(t.kind, self._shapes.get(t.entity)) for t in tracks]

    def kind_of(self, track_id: int) -> int:
        """The kind last published for track ``track_id`` (``Track.KIND_OTHER`` for one
        without votes)."""
        v = self._votes.get(track_id)
        return int(np.argmax(v.score)) if v is not None else Track.KIND_OTHER

    def see_floor(self, floor: FloorPlane | None) -> None:
        """Take the up direction and floor offset from ``floor`` (None: keep the last)."""
        if floor is not None:
            self._up = np.asarray(floor.normal, dtype=np.float64)
            self._offset = float(floor.offset)

    @property
    def up(self) -> npt.NDArray[np.float64]:
        """The up direction in use (the last floor's normal, else the camera's -y)."""
        return self._up

    @property
    def floor_offset(self) -> float | None:
        """The last floor's offset (heights are ``p . up + offset``), None before any."""
        return self._offset


def kind_name(kind: int) -> str:
    """``'head'``, ``'hand'``, ``'foot'`` or ``'other'`` (also for a value out of range)."""
    return KIND_NAMES[kind] if 0 <= kind < len(KIND_NAMES) else 'other'
