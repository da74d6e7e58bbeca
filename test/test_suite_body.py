"""Mocap suite: bodies built from joints (hands, feet, head, variants) and views (facing,
walking direction, camera roll, truncation)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from endeff_ros.core.types import KINECT_640
from endeff_ros.synth.mocap.clip import JOINT_INDEX as J
from endeff_ros.synth.proc_clips import sit_clip, walk_clip, wave_clip
from endeff_ros.synth.render import Camera, default_camera
from endeff_ros.synth.skeleton_body import (
    BodyStyle,
    build_body,
    carry_pose,
    scale_to_height,
    standing_height,
)
from endeff_ros.synth.suite import BagRenderer, BagSpec, PersonSpec
from endeff_ros.synth.views import (
    FARTHEST_M,
    NEAREST_M,
    View,
    aim_camera,
    effective_kind,
    facing,
    place,
)


def _inside(prim, pts: np.ndarray) -> np.ndarray:
    q = (np.atleast_2d(pts) - prim.center) @ prim.rot
    assert prim.kind == 'box'
    return (np.abs(q) <= prim.size + 1e-9).all(1)


@pytest.fixture(scope='module')
def walk() -> np.ndarray:
    return walk_clip(60).positions


def test_hand_is_not_a_ball(walk):
    j = walk[10]
    e = build_body(j)
    for pre in ('l', 'r'):
        parts = [e.prims[e.parts[f'{pre}_{n}']] for n in ('hand', 'fingers', 'thumb')]
        pts = np.concatenate([p.surface_points(600) for p in parts])
        along = j[J[f'{pre}_wrist']] - j[J[f'{pre}_elbow']]
        along /= np.linalg.norm(along)
        normal = e.prims[e.parts[f'{pre}_hand']].rot[:, 2]
        extent_along = np.ptp(pts @ along)
        thickness = np.ptp(pts @ normal)
        assert extent_along > 1.5 * thickness
        assert extent_along > 0.14  # wrist to finger tips of a 1.75 m person


def test_ground_truth_at_part_centres(walk):
    j = walk[25]
    e = build_body(j)
    p = e.prims
    np.testing.assert_allclose(e.gt[0], p[e.parts['head']].center)
    np.testing.assert_allclose(e.gt[3], p[e.parts['l_foot']].center)
    np.testing.assert_allclose(e.gt[4], p[e.parts['r_foot']].center)
    for k, pre in ((1, 'l'), (2, 'r')):
        palm = p[e.parts[f'{pre}_hand']]
        assert e.gt_prims[k] == e.parts[f'{pre}_hand']
        assert _inside(palm, e.gt[k]).all()
        mid = 0.5 * (j[J[f'{pre}_wrist']] + j[J[f'{pre}_hand_end']])
        np.testing.assert_allclose(e.gt[k], mid, atol=1e-9)
    # The shoe reaches from behind the ankle to the toe joint, the crown is at head_top.
    shoe = p[e.parts['l_foot']]
    for joint in ('l_ankle', 'l_toe'):
        q = (j[J[joint]] - shoe.center) @ shoe.rot
        assert abs(q[1]) < shoe.size[1]
    head = p[e.parts['head']]
    top = head.center + head.size[1] * head.rot[:, 1]
    assert np.linalg.norm(top - j[J['head_top']]) < 0.02
    assert list(e.gt_ids) == [0, 1, 2, 3, 4]


@pytest.mark.parametrize('height', [1.5, 1.72, 1.95])
def test_height_variant(walk, height):
    pos = scale_to_height(walk, height)
    assert standing_height(pos) == pytest.approx(height, rel=1e-9)
    assert pos[..., 1].min() == pytest.approx(0.0, abs=1e-9)  # feet stay on the floor
    e = build_body(pos[0], BodyStyle(height_m=height))
    head = e.prims[e.parts['head']]
    top = head.center[1] + head.size[1]
    assert top == pytest.approx(height, rel=0.06)


def test_build_and_clothing_variants(walk):
    j = walk[5]

    def radius(style, part):
        e = build_body(j, style)
        return e.prims[e.parts[part]].size

    slim, heavy = BodyStyle(build='slim'), BodyStyle(build='heavy')
    assert radius(heavy, 'l_thigh')[0] > 1.3 * radius(slim, 'l_thigh')[0]
    assert radius(heavy, 'abdomen')[2] > 1.5 * radius(slim, 'abdomen')[2]
    assert radius(BodyStyle(clothing='sleeves'), 'l_fore')[0] > 1.5 * radius(
        BodyStyle(), 'l_fore')[0]
    plain = build_body(j)
    assert 'coat' not in plain.parts and 'skirt' not in plain.parts
    coat = build_body(j, BodyStyle(clothing='coat'))
    skirt = build_body(j, BodyStyle(clothing='skirt'))
    c, s = coat.prims[coat.parts['coat']], skirt.prims[skirt.parts['skirt']]
    assert c.size[1] > s.size[1]  # the coat is longer than the skirt
    knee_y = 0.5 * (j[J['l_knee'], 1] + j[J['r_knee'], 1])
    assert c.center[1] - c.size[1] < knee_y < s.center[1] - s.size[1] + 0.2
    np.testing.assert_allclose(coat.gt, plain.gt)  # clothes do not move the ground truth


def test_child_has_a_larger_head_for_its_height(walk):
    def head_ratio(style):
        e = build_body(scale_to_height(walk, style.height_m)[0], style)
        return e.prims[e.parts['head']].size[1] / style.height_m

    assert head_ratio(BodyStyle(height_m=1.2, child=True)) > 1.15 * head_ratio(
        BodyStyle(height_m=1.75))


def test_bad_body_input_is_a_clear_error(walk):
    with pytest.raises(ValueError, match='joints'):
        build_body(walk[0, :10])
    with pytest.raises(ValueError, match='build'):
        BodyStyle(build='huge')
    with pytest.raises(ValueError, match='height'):
        BodyStyle(height_m=3.0)


def test_carry_pose_holds_the_box_between_the_hands(walk):
    j, box = carry_pose(walk[10], [0.17, 0.1, 0.12])
    for pre, sign in (('l', 1), ('r', -1)):
        q = (j[J[f'{pre}_wrist']] - box.center) @ box.rot
        assert sign * q[0] > box.size[0]  # each wrist outside its side of the box
        assert abs(q[1]) < box.size[1] + 0.05
    # Arm lengths kept.
    for a, b in (('l_shoulder', 'l_elbow'), ('l_elbow', 'l_wrist')):
        assert np.linalg.norm(j[J[a]] - j[J[b]]) == pytest.approx(
            np.linalg.norm(walk[10, J[a]] - walk[10, J[b]]), rel=1e-6)


@pytest.mark.parametrize(('kind', 'side', 'expect'), [
    ('front', 1, (0, 0, 1)), ('back', 1, (0, 0, -1)), ('side', 1, (1, 0, 0)),
    ('side', -1, (-1, 0, 0))])
def test_facing_yaw(kind, side, expect):
    pos = wave_clip(30).positions  # faces +z, does not travel
    scene, rendered = place(pos, View(kind, 2.5, 1.2, side_sign=side))
    assert rendered == kind
    np.testing.assert_allclose(facing(scene).mean(0), expect, atol=1e-6)
    # Seen from the camera: facing it, the person's left hand is on the image's right.
    cam = aim_camera(scene, View(kind, 2.5, 1.2), KINECT_640)
    u = KINECT_640.project(cam.to_optical(scene[0][[J['l_shoulder'], J['r_shoulder']]]))[:, 0]
    if kind == 'front':
        assert u[0] > u[1] + 20
    elif kind == 'back':
        assert u[0] < u[1] - 20


def test_walking_across_and_towards():
    pos = walk_clip(60).positions
    across, kind = place(pos, View('across', 3.0, 1.2, side_sign=-1))
    assert kind == 'across'
    d = across[-1, J['pelvis']] - across[0, J['pelvis']]
    assert d[0] < -1.0 and abs(d[2]) < 0.1  # walks to the image's left
    assert np.mean(across[:, J['pelvis'], 0]) == pytest.approx(0.0, abs=1e-9)
    towards, kind = place(pos, View('towards', 1.2, 1.2))
    assert kind == 'towards'
    d = towards[-1, J['pelvis']] - towards[0, J['pelvis']]
    assert d[2] > 1.0  # approaches the camera
    assert -towards[:, J['pelvis'], 2].max() >= NEAREST_M - 1e-9
    # A clip that stays in place cannot walk across: rendered as a side view.
    assert effective_kind(wave_clip(30).positions, 'across') == 'side'
    assert effective_kind(wave_clip(30).positions, 'towards') == 'front'


def test_camera_roll_and_paper_default():
    cam = default_camera()
    c, s = np.cos(cam.pitch), np.sin(cam.pitch)
    old = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]) @ np.diag([1.0, -1.0, -1.0])
    np.testing.assert_array_equal(cam.rotation, old)
    cam = dataclasses.replace(cam, pitch=0.0)
    rolled = dataclasses.replace(cam, roll=np.pi / 2)
    p = np.array([[0.5, cam.height, -3.0]])  # right of the camera, at its height
    u0, v0 = KINECT_640.project(cam.to_optical(p))[0]
    u1, v1 = KINECT_640.project(rolled.to_optical(p))[0]
    assert u0 > KINECT_640.cx + 50 and abs(u1 - KINECT_640.cx) < 10
    assert abs(v1 - KINECT_640.cy) > 50
    assert isinstance(rolled, Camera)


def _spec(offset: float, distance: float = 3.0, frames: int = 3) -> BagSpec:
    view = View('front', distance, 1.3, offset_x_m=offset)
    person = PersonSpec('proc_wave', 0, BodyStyle(), view, 3)
    return BagSpec('t', (person,), frames, 'empty', 'none', 'kinect_v1', 5, {})


def test_truncation_flag():
    clips = {'proc_wave': wave_clip(30)}
    centred = BagRenderer(_spec(0.0, 3.2), clips)
    frames = list(centred.frames())
    assert not centred.truncated and all(len(f.gt) == 5 for f in frames)
    cut = BagRenderer(_spec(1.9, 3.2), clips)  # right hand beyond the image's right border
    frames = list(cut.frames())
    assert cut.truncated
    # Only the end-effectors in the field of view are listed: fewer than 5, all inside.
    assert all(0 < len(f.gt) < 5 for f in frames)
    u = KINECT_640.project(frames[0].gt)[:, 0]
    assert ((u >= 0) & (u <= KINECT_640.width - 1)).all()
    assert len(frames[0].gt_ids) == len(frames[0].gt) == len(frames[0].gt_visible)
    assert cut.attributes()['truncated'] is True


def test_people_stay_in_the_activity_area():
    clip = walk_clip(150)
    for kind, distance in (('front', 5.0), ('side', 3.9), ('towards', 3.5), ('back', 1.1)):
        person = PersonSpec(clip.name, 0, BodyStyle(), View(kind, distance, 1.2), 1)
        ren = BagRenderer(BagSpec('w', (person,), 90, 'empty', 'none', 'kinect_v2', 3, {}),
                          {clip.name: clip})
        depth = -ren.joints[0][:, J['pelvis'], 2]
        if depth.max() - depth.min() <= FARTHEST_M - NEAREST_M:
            assert depth.min() >= NEAREST_M - 1e-9 and depth.max() <= FARTHEST_M + 1e-9, kind
        else:  # too long a walk to fit: it stops before the camera
            assert depth.min() == pytest.approx(NEAREST_M), kind


def test_sitting_gets_a_chair_under_the_pelvis():
    clip = sit_clip(60)
    person = PersonSpec(clip.name, 30, BodyStyle(), View('side', 2.5, 1.2), 4)
    spec = BagSpec('s', (person,), 30, 'furnished', 'sit', 'kinect_v1', 9, {})
    ren = BagRenderer(spec, {clip.name: clip})
    assert ren.clutter[0] == 'chair'
    pel = ren.joints[0][:, J['pelvis']]
    low = pel[np.argmin(pel[:, 1])]
    assert low[1] < 0.65
    seat = ren.furniture[0][1][0]
    assert seat.part == 'chair_seat'
    assert np.hypot(*(seat.center - low)[[0, 2]]) < 0.15
    assert 0.05 < low[1] - (seat.center[1] + seat.size[1]) < 0.2


def test_distance_attribute_is_the_rendered_one():
    clip = walk_clip(60)
    person = PersonSpec(clip.name, 0, BodyStyle(), View('towards', 1.3, 1.2), 1)
    ren = BagRenderer(BagSpec('w', (person,), 40, 'empty', 'none', 'kinect_v2', 3, {}),
                      {clip.name: clip})
    pel = ren.joints[0][:, J['pelvis']]
    assert -pel[:, 2].max() == pytest.approx(NEAREST_M)  # pushed back to stop 1 m away
    assert ren.attributes()['distance_m'] == pytest.approx(-pel[:, 2].mean(), abs=0.006)
    assert ren.attributes()['distance_m'] > 1.3
