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
  image's lower border, or resting on nothing in view, only ends by a known floor: on the
  dev split 715 hands of people behind tables were feet by the fraction, 114 feet were not
  by the floor).
- **The head** is the end that goes most directly up from the root: of the ends rising
  :data:`HEAD_MIN_RISE` to :data:`HEAD_MAX_RISE` m above it whose geodesic length exceeds
  their rise by at most :data:`HEAD_MAX_DETOUR`, the one with the smallest excess. A head
  sits straight above the trunk; a hand raised as high has come up the arm (it rises more and
  its path is longer); one in front of the chest rises little for its length. On a body cut
  by the image's lower border the rise has no upper bound: its root may lie at the thighs.
  At most one per entity, and none when no end qualifies (a head hidden behind a raised arm).
- **Hands** are the other ends of a person-like entity.
- **Two decisions learnt** (``scored_kinds``, the default): whether an entity is a person and
  which of a person's ends is the head are taken by two small additive logistic models
  (:class:`KindModels`, :mod:`.additive`) over the same evidence instead of by the thresholds
  above: the person model from the entity's ends, span, lowest and highest points above the
  floor, floor contact, cuts by the image's borders, ends by the floor, head-like ends,
  thickness and the width of its top against its own (:data:`PERSON_FEATURES`); the head model
  from each end's rise, detour, horizontal distance from the root, depth below the entity's
  top, rank by height and the entity's size (:data:`HEAD_FEATURES`). Feet stay the ends by the
  floor. The tests are a cascade in which one threshold missed (a person whom a table or an
  occluder cuts above the floor rests on nothing in view; a person with two ends in view) makes
  every end "other"; the person model weighs the same evidence together. Trained on the dev
  split with chairs, robot arms and stars (``python -m tools.train_kinds``), it made 93.4 /
  93.1 % rather than 86.8 / 88.2 % of the matched ends' kinds right on the dev clip halves held
  out in turn (docs/design.md, "Which part an end is").
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
are one entity (one head between them); with the rules alone, a person that a table or
furniture cuts in the middle rests on nothing in view and keeps the kinds its ends had (new
ends are 0); furniture that moves (so the background does not take it) and is shaped like a
person (tall, three ends or more, one rising like a head) is a person.

Pure numpy: no ROS import (the core's rule).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from .additive import AdditiveModel, read_model
from .types import Track

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy.typing as npt

    from .floor import FloorPlane
    from .single_frame import FrameEstimate
    from .types import Intrinsics

KIND_MODEL_FILE = Path(__file__).with_name('kind_model.json')
"""The committed person and head models (``tools/train_kinds.py`` writes them)."""

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

#: The top slice (m) whose width :attr:`EntityShape.top_width` compares with the entity's: about
#: a head's height.
TOP_SLICE = 0.2

_CAMERA_UP = np.array([0.0, -1.0, 0.0])


class EntityShape(NamedTuple):
    """What the person test needs of one entity: its root's height, the 1st and 99th
    percentiles of its points' heights (m, above the floor where ``on_floor``, else along
    the up direction from an arbitrary origin), and whether the image's lower border cuts it
    (``cut``: its lowest points in the image lie within :data:`CUT_BORDER` of the border),
    or the upper border (``cut_top``: a person close to the camera whose head is out of it),
    and its root's position (``root``, None: not known). ``thickness``: the spread (m, standard
    deviation) of its points along their least direction: a cabinet's or a door's face is a
    plane, a person's body is not. ``top_width``: the width across the view of its top
    :data:`TOP_SLICE` over that of the whole entity: a head on shoulders and arms against a
    cabinet's or a table's top as wide as the rest. Their defaults are a standing person's,
    for a shape known only by its heights.)"""

    root_height: float
    bottom: float
    top: float
    on_floor: bool
    cut: bool = False
    cut_top: bool = False
    root: tuple[float, float, float] | None = None
    thickness: float = 0.1
    top_width: float = 0.4


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
                                      float(top), offset is not None, cut, cut_top,
                                      tuple(float(c) for c in ent.root),
                                      *_spread(pts, h, float(top), up))
    return out


def _spread(pts: npt.NDArray[np.float64], h: npt.NDArray[np.float64], top: float,
            up: npt.NDArray[np.float64]) -> tuple[float, float]:
    """:attr:`EntityShape.thickness` and :attr:`EntityShape.top_width` of an entity's points
    ``pts`` at heights ``h`` (its top at ``top``), widths between the 5th and 95th
    percentiles across the view (horizontal, square to the ray through the points' mean)."""
    if len(pts) < 4:
        return EntityShape._field_defaults['thickness'], EntityShape._field_defaults['top_width']
    mean = pts.mean(axis=0)
    centred = pts - mean
    thickness = float(np.sqrt(max(np.linalg.eigvalsh(centred.T @ centred / len(pts))[0], 0.0)))
    across = np.cross(up, mean)
    norm = float(np.linalg.norm(across))
    if norm < 1e-9:
        return thickness, EntityShape._field_defaults['top_width']
    x = centred @ (across / norm)
    lo, hi = np.percentile(x, [5.0, 95.0])
    upper = x[h >= top - TOP_SLICE]
    if len(upper) < 4 or hi - lo < 1e-3:
        return thickness, 1.0
    tlo, thi = np.percentile(upper, [5.0, 95.0])
    return thickness, float(min((thi - tlo) / (hi - lo), 1.0))


PERSON_FEATURES = ('ends', 'span', 'bottom', 'top', 'on_floor', 'cut', 'cut_top', 'floor_ends',
                   'head_like', 'rules', 'thickness', 'top_width')
"""The person model's evidence about an entity (:func:`kind_evidence`): its ends' count, its
span up, its lowest and highest points' heights above the floor (:data:`NO_FLOOR` without
one), whether it rests on a known floor, whether the image's lower or upper border cuts it,
how many of its ends lie by the floor, how many rise from the root like a head, its
thickness and the width of its top against its own (:class:`EntityShape`), and whether it
passes the person tests (``rules``: what they know of shapes the training never showed;
without it a chair, a star or a robot arm held out of the training was a person in 27-100 %
of its frames, with it a star 41 %, a robot arm 65 %, a chair none; with the widths too, a
star 100 %, a robot arm 70 %, a chair none)."""
HEAD_FEATURES = ('rise', 'detour', 'lateral', 'below_top', 'height_rank', 'height_gap', 'ends',
                 'span', 'cut')
"""The head model's evidence about an end of a person that is not a foot: its rise above the
root, its geodesic length less that rise (the detour of a hand that came up the arm), its
horizontal distance from the root, its depth below the entity's top, its rank by height and
its height over the highest other such end, the entity's ends, span and cut."""
NO_FLOOR = -1.0
"""``bottom`` and ``top`` of an entity when no floor is known (below any height above it)."""
FLOOR_BAND = 0.1
"""An entity's lowest points (``bottom``) closer to the floor than this (m) read as this: on
the floor. The renders put a person's lowest points 4-7 cm up and a chair's 3-4 cm, a
difference no real sensor keeps; unclipped, the model learnt it, and a standing person whose
lowest points were 2 cm up was no person."""
PERSON_LOGIT = -1.0
"""An entity is a person when the person model's log-odds exceed this (a chance of 0.27): a
missed person costs more than a chair's legs called feet, yet lower, shapes the models were
not fitted with become people. On the dev split's clip halves held out in turn (``python -m
tools.train_kinds fit --holdout``), -0.5 / -1.0 / -1.5 made 93.0 / 93.3 / 94.2 % of matched
ends' kinds right; of the held-out generic shapes' ends, a chair's were not 0 in 0.1 / 0.1 /
19 %, a robot arm's and a star's in 91 % at each (their narrow tops read as heads)."""
HEAD_LOGIT = 0.0
"""The most head-like end of a person is its head when the head model's log-odds exceed this
(even odds); none is, when the head is hidden."""


class KindEvidence(NamedTuple):
    """Per end of a frame: its entity (-1: none known), whether it lies by the floor
    (``low``: a foot when the entity is a person), its entity's :data:`PERSON_FEATURES` and
    its own :data:`HEAD_FEATURES`, and what the rules say (``rules_person``: the entity passes
    the person tests; ``rules_head``: the rules' head)."""

    entities: npt.NDArray[np.intp]
    low: npt.NDArray[np.bool_]
    person: npt.NDArray[np.float64]
    head: npt.NDArray[np.float64]
    rules_person: npt.NDArray[np.bool_]
    rules_head: npt.NDArray[np.bool_]


def kind_evidence(positions: npt.NDArray[np.float64], geodesics: npt.NDArray[np.float64],
                  entities: npt.NDArray[np.intp], shapes: dict[int, EntityShape],
                  up: npt.NDArray[np.float64], offset: float | None) -> KindEvidence:
    """The :class:`KindEvidence` of (M, 3) ends ``positions`` with (M,) geodesic lengths
    ``geodesics`` to the roots of their (M,) ``entities``, from the entities' ``shapes``
    (:func:`entity_shapes`) and the up direction and floor offset they were measured with."""
    m = len(positions)
    ev = KindEvidence(np.full(m, -1, dtype=np.intp), np.zeros(m, dtype=bool),
                      np.zeros((m, len(PERSON_FEATURES))), np.zeros((m, len(HEAD_FEATURES))),
                      np.zeros(m, dtype=bool), np.zeros(m, dtype=bool))
    heights = positions @ up + (offset or 0.0) if m else np.zeros(0)
    for e in np.unique(entities):
        shape = shapes.get(int(e))
        if shape is None:
            continue
        mine = np.flatnonzero(entities == e)
        ev.entities[mine] = e
        h = heights[mine]
        span = shape.top - shape.bottom
        floor_level = 0.0 if shape.on_floor else shape.bottom
        rise = h - shape.root_height
        grounded = not shape.on_floor or shape.bottom < FLOOR_CONTACT
        if shape.cut or not grounded:
            # The legs are out of the image or behind something (a table, an occluder): only
            # an end by the floor is a foot; the lowest ends in view are hands.
            low = shape.on_floor & (h < FOOT_HEIGHT)
        else:
            low = (h - floor_level < FOOT_HEIGHT) | (h - shape.bottom < FOOT_FRACTION * span)
        low &= rise < 0
        ev.low[mine] = low
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
        ev.rules_person[mine] = standing or partial
        upper = np.flatnonzero(~low & _head_like(rise, geo, cut=shape.cut))
        if upper.size:
            ev.rules_head[mine[upper[np.argmin(geo[upper] - rise[upper])]]] = True
        ev.person[mine] = [
            min(len(mine), 8), min(span, 2.5),
            np.clip(shape.bottom, FLOOR_BAND, 2.0) if shape.on_floor else NO_FLOOR,
            np.clip(shape.top, -1.0, 2.5) if shape.on_floor else NO_FLOOR,
            shape.on_floor, shape.cut, shape.cut_top, min(floor_ends, 4),
            min(np.count_nonzero(_head_like(rise, geo)), 3), standing or partial,
            min(shape.thickness, 0.3), shape.top_width]
        ev.head[mine] = _head_features(positions[mine], h, rise, geo, low, shape, span, up)
    return ev


def _head_features(positions: npt.NDArray[np.float64], h: npt.NDArray[np.float64],
                   rise: npt.NDArray[np.float64], geo: npt.NDArray[np.float64],
                   low: npt.NDArray[np.bool_], shape: EntityShape, span: float,
                   up: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """:data:`HEAD_FEATURES` of one entity's ends (rank and gap among its ends not ``low``;
    the horizontal distance from its root, or from its ends' mean when the root is not
    known)."""
    root = np.asarray(shape.root) if shape.root is not None else positions.mean(axis=0)
    d = positions - root
    lateral = np.linalg.norm(d - np.outer(d @ up, up), axis=1)
    upper_h = np.where(low, -np.inf, h)
    order = np.argsort(-upper_h)
    rank = np.empty(len(h))
    rank[order] = np.arange(len(h))
    gap = np.ones(len(h))
    if len(h) > 1:
        # The highest other end: the highest, except for the highest itself (the second).
        others = np.where(rank == 0, upper_h[order[1]], upper_h[order[0]])
        gap = np.where(np.isfinite(others), np.clip(h - others, -1.0, 1.0), 1.0)
    return np.column_stack([
        np.clip(rise, -1.0, 2.0), np.clip(geo - rise, -0.5, 2.0), np.minimum(lateral, 1.5),
        np.clip(shape.top - h, -0.3, 2.0), np.minimum(rank, 3), gap,
        np.full(len(h), min(len(h), 8)), np.full(len(h), min(span, 2.5)),
        np.full(len(h), float(shape.cut))])


def decide_kinds(ev: KindEvidence, prior: npt.NDArray[np.float64] | None = None,
                 models: KindModels | None = None) -> npt.NDArray[np.intp]:
    """One frame's kind (``Track.KIND_*``) per end from its evidence; -1 where the frame says
    nothing (an end without a known entity). ``prior`` (M,): each end's share of person votes
    so far (:data:`PERSON_MEMORY`). ``models``: the person and head models decide (see
    :class:`KindModels`); None: the rules of the module."""
    kinds = np.where(ev.entities >= 0, Track.KIND_OTHER, -1).astype(np.intp)
    m = len(kinds)
    prior = np.zeros(m) if prior is None else np.asarray(prior, dtype=np.float64)
    person_logit = models.person.logit(ev.person) if models is not None and m else None
    for e in np.unique(ev.entities[ev.entities >= 0]):
        mine = np.flatnonzero(ev.entities == e)
        person = (person_logit[mine[0]] > PERSON_LOGIT if person_logit is not None
                  else ev.rules_person[mine[0]])
        if not (person or prior[mine].mean() > PERSON_MEMORY):
            continue
        low = ev.low[mine]
        kinds[mine] = np.where(low, Track.KIND_FOOT, Track.KIND_HAND)
        if models is None:
            kinds[mine[ev.rules_head[mine]]] = Track.KIND_HEAD
            continue
        upper = mine[~low]
        if upper.size:
            z = models.head.logit(ev.head[upper])
            if z.max() > HEAD_LOGIT:
                kinds[upper[np.argmax(z)]] = Track.KIND_HEAD
    return kinds


def frame_kinds(positions: npt.NDArray[np.float64], geodesics: npt.NDArray[np.float64],
                entities: npt.NDArray[np.intp], shapes: dict[int, EntityShape],
                up: npt.NDArray[np.float64], offset: float | None,
                prior: npt.NDArray[np.float64] | None = None,
                models: KindModels | None = None) -> npt.NDArray[np.intp]:
    """One frame's kind per end (:func:`decide_kinds` of :func:`kind_evidence`)."""
    return decide_kinds(kind_evidence(positions, geodesics, entities, shapes, up, offset),
                        prior, models)


class PersonModel(AdditiveModel):
    """The chance that an entity is a person, from its :data:`PERSON_FEATURES`."""

    COLUMNS = PERSON_FEATURES
    WHAT = 'person'


class HeadModel(AdditiveModel):
    """The chance that an end of a person (not a foot) is its head, from its
    :data:`HEAD_FEATURES`."""

    COLUMNS = HEAD_FEATURES
    WHAT = 'head'


@dataclass(frozen=True)
class KindModels:
    """The learnt part of the kinds (``scored_kinds``): an entity is a person when the
    person model says so (:data:`PERSON_LOGIT`) instead of by the person tests; the head is a
    person's most head-like end by the head model (:data:`HEAD_LOGIT`) instead of the
    straightest riser. Feet stay the ends by the floor, hands the rest."""

    person: PersonModel
    head: HeadModel

    @classmethod
    def load(cls, path: str | Path = KIND_MODEL_FILE) -> KindModels:
        """The models in ``path`` (default the committed :data:`KIND_MODEL_FILE`); raises
        ValueError naming the file when it cannot be read or is malformed."""
        return read_model(path, lambda data: cls(PersonModel.from_json(data['person']),
                                                 HeadModel.from_json(data['head'])))

    def to_json(self) -> dict[str, Any]:
        """The model file's content."""
        return {'person': self.person.to_json(), 'head': self.head.to_json()}


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


def person_points(estimate: FrameEstimate, entities: Sequence[int],
                  flags: Sequence[bool] | None) -> npt.NDArray[np.float64] | None:
    """The points of the entities of ``estimate`` that hold an end flagged ``flags`` (aligned
    with ``entities``, each end's entity index), for the static background's entities of the
    start (:meth:`.background.BackgroundModel.mark`): a person's flag covers their own points,
    not furniture that the depth labelling joins to them. None (the whole component keeps its
    flag, people first) without flags or when a flagged end's entity is not known."""
    if flags is None:
        return None
    flagged = {int(e) for e, f in zip(entities, flags, strict=True) if f}
    if not flagged <= {ent.entity for ent in estimate.entities}:
        return None
    return estimate.points[np.isin(estimate.entity, list(flagged))]


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


def judged_candidates(entities: Sequence[int],
                      flags: Sequence[bool] | npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    """Per candidate of a frame estimate (``entities``: each one's entity index, in
    :meth:`FrameEstimate.positions` order, as for :func:`person_points`), given its
    :func:`person_candidates` ``flags``: whether this frame could tell if it is a person's.
    A flagged end is; an unflagged one only on an entity that shows at least
    :data:`MIN_PERSON_ENDS` ends: with fewer, the person tests fail whatever the entity is (a
    still person of whom one frame shows two ends), and the frame says nothing about it. For
    a caller without tracks, whose kinds have no history (the tracker's tracks carry
    theirs): the static background counts only these frames
    (:meth:`.background.BackgroundModel.mark`)."""
    flags = np.asarray(flags, dtype=bool).reshape(-1)
    if len(entities) == 0:
        return flags.copy()
    _, inverse, counts = np.unique(np.asarray(entities, np.intp), return_inverse=True,
                                   return_counts=True)
    return flags | (counts[inverse] >= MIN_PERSON_ENDS)


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
    models: KindModels | None = None  # None: the rules decide (``scored_kinds`` off)
    evidence: KindEvidence | None = None  # the last labelled frame's (tools.train_kinds)
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
                           self._up, self._offset, models=self.models)

    def use_models(self, on: bool) -> None:
        """Decide with the committed :class:`KindModels` (``scored_kinds``; loaded when first
        needed, a broken file raising ValueError) or, ``on`` false, with the rules alone."""
        if not on:
            self.models = None
        elif self.models is None:
            self.models = KindModels.load()

    def label_shapes(self, tracks: Sequence[Track],
                     shapes: dict[int, EntityShape]) -> list[Track]:
        """:meth:`label` from the entities' shapes (:func:`entity_shapes`, with this
        labeller's up and floor): the offline tools' entry."""
        positions = np.array([t.position for t in tracks], dtype=np.float64).reshape(-1, 3)
        self.evidence = kind_evidence(
            positions, np.array([t.geodesic for t in tracks], dtype=np.float64),
            np.array([t.entity for t in tracks], dtype=np.intp), shapes, self._up, self._offset)
        kinds = self.label_evidence([t.id for t in tracks], [t.age for t in tracks],
                                    self.evidence)
        return [replace(t, kind=k) for t, k in zip(tracks, kinds, strict=True)]

    def label_evidence(self, ids: Sequence[int], ages: Sequence[int],
                       evidence: KindEvidence) -> list[int]:
        """The kinds of the ends of one frame from their track ``ids`` and ``ages`` and their
        ``evidence`` (:func:`kind_evidence`): :meth:`label`'s last step, and the offline
        replay of ``tools.train_kinds``."""
        self._frame += 1
        kinds = self._vote(self._histories(ids, ages), evidence)
        self._forget()
        return kinds

    def _histories(self, ids: Sequence[int], ages: Sequence[int]) -> list[_Votes]:
        """Each track's votes, decayed to this frame (new ones for new tracks)."""
        history = []
        for i, age in zip(ids, ages, strict=True):
            v = self._votes.get(i)
            if v is None or age <= v.age:  # a new track, or an id given out again
                v = self._votes[i] = _Votes()
            v.score *= self.decay ** (self._frame - v.last) if v.last else 1.0
            v.last, v.age = self._frame, age
            history.append(v)
        return history

    def _vote(self, history: list[_Votes], evidence: KindEvidence) -> list[int]:
        """Add this frame's votes (:func:`decide_kinds`) to ``history``; each end's kind is
        its track's most voted."""
        prior = np.array([v.score[1:].sum() / v.score.sum() if v.score.sum() > 0 else 0.0
                          for v in history])
        kinds = []
        for vote, v in zip(decide_kinds(evidence, prior, self.models), history, strict=True):
            if vote >= 0:
                v.score[vote] += 1.0
            kinds.append(int(np.argmax(v.score)))
        return kinds

    def _forget(self) -> None:
        """Drop the votes of tracks absent :data:`FORGET_FRAMES` frames (every so often)."""
        if self._frame % FORGET_FRAMES == 0:
            self._votes = {i: v for i, v in self._votes.items()
                           if self._frame - v.last <= FORGET_FRAMES}

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
