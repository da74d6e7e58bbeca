"""Head, hand, foot or other (``Track.kind``): the rules of core/kinds.py and their memory."""

from __future__ import annotations

import numpy as np
import pytest

from endeff_ros.core.kinds import (
    EntityShape,
    KindLabeller,
    entity_shapes,
    frame_kinds,
    kind_name,
)
from endeff_ros.core.types import Track

UP = np.array([0.0, -1.0, 0.0])  # the camera level: up is -y
FLOOR = 1.1  # camera 1.1 m above the floor: height = -y + 1.1
HEAD, HAND, FOOT, OTHER = Track.KIND_HEAD, Track.KIND_HAND, Track.KIND_FOOT, Track.KIND_OTHER


def _at(x: float, h: float, z: float = 3.0) -> list[float]:
    """A point ``h`` m above the floor, ``x`` m to the right, ``z`` m ahead."""
    return [x, FLOOR - h, z]


def _kinds(ends: list[tuple[list[float], float]], shape: EntityShape) -> list[int]:
    pos = np.array([p for p, _ in ends])
    geo = np.array([g for _, g in ends])
    return frame_kinds(pos, geo, np.zeros(len(ends), dtype=np.intp), {0: shape}, UP,
                       FLOOR).tolist()


STANDING = EntityShape(root_height=1.0, bottom=0.02, top=1.75, on_floor=True)


def test_a_standing_person_has_a_head_two_hands_and_two_feet():
    ends = [(_at(0.0, 1.6), 0.6), (_at(-0.6, 1.0), 0.85), (_at(0.6, 1.1), 0.85),
            (_at(-0.15, 0.08), 1.0), (_at(0.15, 0.08), 1.0)]
    assert _kinds(ends, STANDING) == [HEAD, HAND, HAND, FOOT, FOOT]


def test_a_hand_raised_above_the_head_is_no_head():
    """The raised hand is the highest end, but it came up the arm: its geodesic length is
    much more than its rise, the head's about equal to it."""
    ends = [(_at(0.35, 2.0), 1.25), (_at(0.0, 1.6), 0.62), (_at(-0.3, 0.9), 0.8),
            (_at(-0.15, 0.08), 1.0), (_at(0.15, 0.08), 1.0)]
    assert _kinds(ends, STANDING) == [HAND, HEAD, HAND, FOOT, FOOT]


def test_a_chair_a_floating_star_and_a_robot_arm_are_other():
    chair = EntityShape(root_height=0.45, bottom=0.0, top=0.96, on_floor=True)
    legs = [(_at(x, 0.03, z), 0.5) for x in (-0.2, 0.2) for z in (2.8, 3.2)]
    back = [(_at(x, 0.96, 3.2), 0.6) for x in (-0.23, 0.23)]
    assert _kinds(legs + back, chair) == [OTHER] * 6
    star = EntityShape(root_height=1.15, bottom=0.55, top=1.75, on_floor=True)
    arms = [(_at(0.6 * np.cos(a), 1.15 + 0.6 * np.sin(a)), 0.55)
            for a in np.pi / 2 + 2 * np.pi * np.arange(5) / 5]
    assert _kinds(arms, star) == [OTHER] * 5
    arm = EntityShape(root_height=0.6, bottom=0.0, top=1.35, on_floor=True)
    assert _kinds([(_at(0.4, 1.3), 1.0), (_at(0.0, 0.03), 0.6)], arm) == [OTHER] * 2


def test_a_person_cut_at_the_waist_by_the_image_has_a_head_and_hands():
    """Close to the camera the image's lower border cuts the body: what is in view rests on
    nothing (its lowest points 0.6 m above the floor, as a star's), yet the upper body test
    holds; no end is a foot. The same shape not cut by the border floats: other."""
    close = EntityShape(root_height=1.05, bottom=0.6, top=1.75, on_floor=True, cut=True)
    ends = [(_at(0.0, 1.65, 1.3), 0.62), (_at(-0.35, 1.0, 1.0), 0.7),
            (_at(0.3, 0.7, 1.0), 0.75)]
    assert _kinds(ends, close) == [HEAD, HAND, HAND]
    assert _kinds(ends, close._replace(cut=False)) == [OTHER] * 3


def test_a_cut_body_whose_root_lies_at_the_thighs_still_has_a_head():
    """A person filling the image, cut by its lower border: the graph's root lands on the
    thighs, 1.5 m below the head, beyond the rise a standing person's head has; the head
    still goes straight up from it and is a head. Not cut, the same rise is a raised hand."""
    close = EntityShape(root_height=0.1, bottom=-0.2, top=1.7, on_floor=True, cut=True)
    ends = [(_at(0.0, 1.62, 1.0), 1.6), (_at(-0.4, 0.9, 0.9), 1.3), (_at(0.4, 0.8, 0.9), 1.4)]
    assert _kinds(ends, close) == [HEAD, HAND, HAND]
    assert _kinds(ends, close._replace(cut=False))[0] != HEAD


def test_legs_below_an_image_cutting_off_the_head_are_feet():
    legs = EntityShape(root_height=0.9, bottom=0.02, top=1.0, on_floor=True, cut_top=True)
    ends = [(_at(-0.15, 0.08), 1.0), (_at(0.15, 0.08), 1.0)]
    assert _kinds(ends, legs) == [FOOT, FOOT]
    assert _kinds(ends, legs._replace(cut_top=False)) == [OTHER] * 2  # two ends: too few


def test_an_end_of_an_unknown_entity_gets_no_vote():
    pos = np.array([_at(0.0, 1.6)])
    assert frame_kinds(pos, np.array([0.6]), np.array([3]), {0: STANDING}, UP,
                       FLOOR).tolist() == [-1]


def _labeller() -> KindLabeller:
    from endeff_ros.core.floor import FloorPlane

    labeller = KindLabeller()
    labeller.see_floor(FloorPlane(UP, FLOOR))
    return labeller


def _track(tid: int, position: list[float], geodesic: float, age: int) -> Track:
    return Track(id=tid, entity=0, position=np.array(position), geodesic=geodesic,
                 confidence=1.0, state=Track.DETECTED, age=age)


def _person(frame: int, right_foot_height: float = 0.08) -> list[Track]:
    return [_track(1, _at(0.0, 1.6), 0.6, frame), _track(2, _at(-0.6, 1.0), 0.85, frame),
            _track(3, _at(0.6, 1.1), 0.85, frame), _track(4, _at(-0.15, 0.08), 1.0, frame),
            _track(5, _at(0.15, right_foot_height), 1.0, frame)]


def test_a_foot_raised_for_a_moment_stays_a_foot_raised_for_long_becomes_a_hand():
    labeller = _labeller()
    for frame in range(1, 31):  # a second of standing
        out = labeller.label_shapes(_person(frame), {0: STANDING})
    assert [t.kind for t in out] == [HEAD, HAND, HAND, FOOT, FOOT]
    for frame in range(31, 36):  # a kick: the right foot 0.9 m up for 5 frames
        out = labeller.label_shapes(_person(frame, 0.9), {0: STANDING})
        assert out[4].kind == FOOT
    for frame in range(36, 96):  # held up for two seconds
        out = labeller.label_shapes(_person(frame, 0.9), {0: STANDING})
    assert out[4].kind == HAND


def test_a_person_who_lies_down_keeps_being_a_person_and_a_new_id_starts_afresh():
    labeller = _labeller()
    for frame in range(1, 31):
        labeller.label_shapes(_person(frame), {0: STANDING})
    lying = EntityShape(root_height=0.15, bottom=0.0, top=0.35, on_floor=True)
    ends = [_track(1, _at(0.9, 0.12), 0.6, 31), _track(2, _at(0.5, 0.3), 0.8, 31),
            _track(4, _at(-0.9, 0.1), 1.0, 31)]
    out = labeller.label_shapes(ends, {0: lying})
    assert [t.kind for t in out] == [HEAD, HAND, FOOT]  # the votes of the standing frames
    # Id 1 given to a new track (age 1): its history is not the old head's.
    fresh = [_track(1, _at(0.9, 0.12), 0.6, 1)]
    assert labeller.label_shapes(fresh, {0: lying})[0].kind == OTHER
    # Nor does anything stick to an entity never person-like.
    other = _labeller()
    for frame in range(1, 31):
        out = other.label_shapes([_track(9, _at(0.0, 0.1), 0.5, frame)], {0: lying})
    assert out[0].kind == OTHER


def test_entity_shapes_measure_heights_above_the_floor_and_the_cut():
    from endeff_ros.core.floor import FloorPlane
    from endeff_ros.core.single_frame import EntityEstimate, FrameEstimate
    from endeff_ros.core.types import KINECT_640

    rng = np.random.default_rng(0)
    h = rng.uniform(0.0, 1.8, 500)
    pts = np.stack([rng.uniform(-0.2, 0.2, 500), FLOOR - h, np.full(500, 3.0)], axis=1)
    ent = EntityEstimate(0, np.array(_at(0.0, 1.0)), [], None, np.arange(500))
    est = FrameEstimate(points=pts, band=np.zeros(500, int), subband=np.zeros(500, int),
                        entity=np.zeros(500, int), entities=[ent], unreachable=0,
                        floor=FloorPlane(UP, FLOOR))
    shape = entity_shapes(est, UP, FLOOR, KINECT_640)[0]
    assert shape.root_height == pytest.approx(1.0)
    assert shape.bottom == pytest.approx(0.0, abs=0.05)
    assert shape.top == pytest.approx(1.8, abs=0.05)
    assert shape.on_floor and not shape.cut  # the feet, 3 m ahead, are well inside the image
    near = est.points.copy()
    near[:, 2] = 1.2  # the same body at 1.2 m: its lower half is below the image
    shape = entity_shapes(FrameEstimate(points=near, band=est.band, subband=est.subband,
                                        entity=est.entity, entities=[ent], unreachable=0),
                          UP, FLOOR, KINECT_640)[0]
    assert shape.cut


def test_entity_shapes_tell_a_head_on_shoulders_from_a_cabinet():
    """``top_width``: a head's top slice is narrow against the shoulders' span, a cabinet's
    as wide as the rest; ``thickness``: a body has depth, a cabinet's front is a plane."""
    from endeff_ros.core.single_frame import EntityEstimate, FrameEstimate

    rng = np.random.default_rng(1)

    def shape(width_at, depth: float):
        h = rng.uniform(0.0, 1.8, 3000)
        x = rng.uniform(-0.5, 0.5, 3000) * width_at(h)
        z = 3.0 + rng.uniform(-depth, depth, 3000)
        pts = np.stack([x, FLOOR - h, z], axis=1)
        ent = EntityEstimate(0, np.array(_at(0.0, 1.0)), [], None, np.arange(3000))
        est = FrameEstimate(points=pts, band=np.zeros(3000, int), subband=np.zeros(3000, int),
                            entity=np.zeros(3000, int), entities=[ent], unreachable=0)
        return entity_shapes(est, UP, FLOOR)[0]

    person = shape(lambda h: np.where(h > 1.55, 0.18, 0.45), 0.12)
    cabinet = shape(lambda h: np.full_like(h, 0.6), 0.01)
    assert person.top_width < 0.5 < 0.9 < cabinet.top_width
    assert cabinet.thickness < 0.02 < 0.05 < person.thickness


def test_the_person_model_weighs_a_top_as_wide_as_the_rest_against_a_person(models):
    """The same entity with a head's narrow top and with a top as wide as the rest (a
    cabinet, a shelf): the person model's log-odds fall."""
    from endeff_ros.core.kinds import PERSON_FEATURES

    row = np.array([[5, 1.7, 0.1, 1.7, 1, 0, 0, 2, 1, 1, 0.08, 0.3]])
    wide = row.copy()
    wide[0, PERSON_FEATURES.index('top_width')] = 1.0
    assert models.person.logit(wide)[0] < models.person.logit(row)[0] - 1.0


def test_kind_names():
    assert [kind_name(k) for k in (0, 1, 2, 3, 7)] == ['other', 'head', 'hand', 'foot', 'other']


def _synthetic_kinds(sequence: str) -> tuple[int, int, int]:
    """(matched ends, of the right kind, of kind other) of the tracker over a quick render
    of a paper-suite sequence, ends matched to the labels within 0.15 m."""
    from endeff_ros.core.tracker import Tracker
    from endeff_ros.core.types import KINECT_640, RGBDFrame
    from endeff_ros.evaluate import is_person_sequence
    from endeff_ros.scoring import kinds_of_ids, score_frame
    from endeff_ros.synth.frames import render_sequence

    person = is_person_sequence(sequence, {})
    tracker = Tracker()
    matched = right = other = 0
    for f in render_sequence(sequence, quick=True):
        if f.depth is None:
            continue
        result = tracker.update(RGBDFrame(f.stamp_ns, 'camera', f.depth, KINECT_640, f.color))
        truth = kinds_of_ids(f.gt_ids, person=person)
        score = score_frame(result.positions(), f.gt)
        names = ['other', 'head', 'hand', 'foot']
        for est, gt in score.matches:
            matched += 1
            right += names[result.tracks[est].kind] == truth[gt]
        other += sum(t.kind == OTHER for t in result.tracks)
    return matched, right, other


@pytest.mark.parametrize('sequence', ['two_people', 'jumping_jacks'])
def test_tracked_people_get_their_kinds(sequence):
    matched, right, _ = _synthetic_kinds(sequence)
    assert matched >= 20
    assert right >= 0.9 * matched


@pytest.mark.parametrize('sequence', ['chair', 'robot_arm', 'star'])
def test_tracked_generic_entities_are_other(sequence):
    matched, right, _ = _synthetic_kinds(sequence)
    assert matched >= 5
    assert right >= 0.95 * matched


# -- the person and head models (scored_kinds) ----------------------------------------------


@pytest.fixture(scope='module')
def models():
    from endeff_ros.core.kinds import KindModels

    return KindModels.load()


def _scored(ends: list[tuple[list[float], float]], shape: EntityShape, models) -> list[int]:
    pos = np.array([p for p, _ in ends])
    geo = np.array([g for _, g in ends])
    return frame_kinds(pos, geo, np.zeros(len(ends), dtype=np.intp), {0: shape}, UP, FLOOR,
                       models=models).tolist()


def test_the_models_give_a_standing_person_a_head_hands_and_feet(models):
    shape = STANDING._replace(root=tuple(_at(0.0, 1.0)))
    ends = [(_at(0.0, 1.6), 0.6), (_at(-0.6, 1.0), 0.85), (_at(0.6, 1.1), 0.85),
            (_at(-0.15, 0.08), 1.0), (_at(0.15, 0.08), 1.0)]
    assert _scored(ends, shape, models) == [HEAD, HAND, HAND, FOOT, FOOT]
    raised = [(_at(0.35, 2.0), 1.25), (_at(0.0, 1.6), 0.62), (_at(-0.3, 0.9), 0.8),
              (_at(-0.15, 0.08), 1.0), (_at(0.15, 0.08), 1.0)]
    assert _scored(raised, shape, models) == [HAND, HEAD, HAND, FOOT, FOOT]


def test_the_models_leave_a_chair_and_a_robot_arm_other(models):
    chair = EntityShape(root_height=0.45, bottom=0.0, top=0.96, on_floor=True,
                        root=tuple(_at(0.0, 0.45)))
    legs = [(_at(x, 0.03, z), 0.5) for x in (-0.2, 0.2) for z in (2.8, 3.2)]
    back = [(_at(x, 0.96, 3.2), 0.6) for x in (-0.23, 0.23)]
    assert _scored(legs + back, chair, models) == [OTHER] * 6
    arm = EntityShape(root_height=0.6, bottom=0.0, top=1.35, on_floor=True,
                      root=tuple(_at(0.0, 0.6)))
    assert _scored([(_at(0.4, 1.3), 1.0), (_at(0.0, 0.03), 0.6)], arm, models) == [OTHER] * 2


def test_hands_of_a_person_behind_a_table_are_no_feet():
    """A table hides the legs: what is in view rests on nothing (its lowest points 0.75 m
    above the floor). Its lowest ends are hands on the table, not feet: for such an entity
    only an end by the floor is a foot (as for a body the image's border cuts)."""
    from endeff_ros.core.kinds import kind_evidence

    seated = EntityShape(root_height=1.0, bottom=0.75, top=1.75, on_floor=True)
    ends = np.array([_at(0.0, 1.62), _at(-0.45, 0.78), _at(0.45, 0.8), _at(0.2, 0.1)])
    ev = kind_evidence(ends, np.array([0.62, 0.9, 0.9, 1.1]), np.zeros(4, dtype=np.intp),
                       {0: seated}, UP, FLOOR)
    # In the lowest 30 % of the span in view and below the root, yet hands; a foot seen
    # below the table is by the floor.
    assert ev.low.tolist() == [False, False, False, True]


def test_the_replay_of_the_evidence_gives_the_kinds_label_gives(models):
    """``label_evidence`` (the offline replay of tools.train_kinds) from the evidence that
    ``label_shapes`` kept gives the same kinds, vote history included."""
    from endeff_ros.core.floor import FloorPlane

    live, replay = KindLabeller(models=models), KindLabeller(models=models)
    live.see_floor(FloorPlane(UP, FLOOR))
    shape = STANDING._replace(root=tuple(_at(0.0, 1.0)))
    for frame in range(1, 40):
        tracks = _person(frame, 0.08 if frame < 20 else 0.9)
        out = live.label_shapes(tracks, {0: shape})
        again = replay.label_evidence([t.id for t in tracks], [t.age for t in tracks],
                                      live.evidence)
        assert again == [t.kind for t in out]


def test_a_broken_kind_model_file_is_named(tmp_path):
    from endeff_ros.core.kinds import KindModels

    broken = tmp_path / 'kinds.json'
    broken.write_text('{"person": {"bias": 0, "features": []}}', encoding='utf-8')
    with pytest.raises(ValueError, match='kinds.json'):
        KindModels.load(broken)
    with pytest.raises(ValueError, match='nowhere.json'):
        KindModels.load(tmp_path / 'nowhere.json')


def test_train_kinds_collects_fits_and_replays_a_rooms_bag(room_bag, tmp_path):
    """``tools.train_kinds``: collect keeps every published end of every frame with its
    evidence and truth; fit writes models that load; the replay's confusion counts the
    matched ends of people."""
    import json

    from endeff_ros.core.kinds import KindModels
    from tools.train_kinds import load, main

    bag, _ = room_bag
    assert main(['collect', str(bag), '--out', str(tmp_path / 'c')]) == 0
    (data,) = load([tmp_path / 'c'])
    assert len(data['person']) == len(data['head']) == len(data['truth']) > 0
    matched = int(np.count_nonzero(data['truth'] >= 1))
    assert matched > 0  # premise: ends matched to the walking person
    model = tmp_path / 'm.json'
    assert main(['fit', str(tmp_path / 'c'), '--model', str(model), '--json',
                 str(tmp_path / 'r.json')]) == 0
    KindModels.load(model)
    report = json.loads((tmp_path / 'r.json').read_text(encoding='utf-8'))
    assert report['models']['matched'] == report['rules']['matched'] == matched
    assert 0.0 <= report['models']['accuracy'] <= 1.0


def test_first_taken_finds_when_the_start_s_person_and_furniture_were_taken_for_people():
    """``tools.train_kinds.first_taken``: the first frame an end of the person in view at the
    start is not 0, and the same for an entity of the start that never holds a person's end."""
    from tools.train_kinds import NEVER, first_taken

    frames = np.repeat(np.arange(40), 2)  # per frame: the person's end (id 1), a shelf's (id 2)
    bag = {'frame': frames, 'entities': np.tile([0, 1], 40), 'id': np.tile([1, 2], 40),
           'truth': np.tile([2, -1], 40)}
    kinds = np.zeros(80, dtype=np.intp)
    kinds[(frames >= 10) & (bag['id'] == 1)] = 2
    kinds[(frames == 20) & (bag['id'] == 2)] = 1
    assert first_taken(bag, kinds) == ([10], [20])
    assert first_taken(bag, np.zeros(80, dtype=np.intp)) == ([NEVER], [NEVER])
    bag['truth'] = np.where(frames < 6, -1, bag['truth'])  # the person comes later
    assert first_taken(bag, kinds)[0] == []
