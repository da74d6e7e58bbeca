"""Rooms suite: pairs of bags that differ only by their furniture, and the panning camera."""

from __future__ import annotations

import argparse
import dataclasses
import json
import re

import numpy as np
import pytest
import yaml

from endeff_ros.attributes import ATTRIBUTES_KEY
from endeff_ros.synth import cli as synth_cli
from endeff_ros.synth.frames import PERIOD_NS, T0_NS
from endeff_ros.synth.mocap.clip import MotionClip
from endeff_ros.synth.pan import Pan
from endeff_ros.synth.proc_clips import sit_clip, walk_clip, wave_clip
from endeff_ros.synth.render import STATIC, render
from endeff_ros.synth.rooms_suite import (
    QUICK_PAIR_FRAMES,
    QUICK_PAN_FRAMES,
    QUICK_PAN_START_S,
    rooms_specs,
)
from endeff_ros.synth.skeleton_body import BodyStyle
from endeff_ros.synth.suite import DETAILS_KEY, BagRenderer, BagSpec, PersonSpec, write_bag
from endeff_ros.synth.views import View

NAME = re.compile(r'^(dev|test)__[A-Za-z0-9_-]+__(\d{3}|m\d\d)-(front|side|back|across|towards)-'
                  r'([a-z0-9_]+)-(empty|furnished)-p(\d)-(static|pan)(-(still|slow)-[a-z0-9-]+)?$')


@pytest.fixture(scope='module')
def clips():
    return [walk_clip(60, name='walk_a'), walk_clip(60, 1.0, 'walk_b', 'test'),
            wave_clip(40, name='wave_a', split='dev'), wave_clip(40, name='wave_b'),
            sit_clip(60)]


@pytest.fixture(scope='module')
def specs(clips):
    return rooms_specs(clips, quick=True)


def test_quick_specs_come_in_named_pairs(clips, specs):
    assert len(specs) == 16 and specs == rooms_specs(clips, quick=True)
    assert specs != rooms_specs(clips, quick=True, seed=1)
    assert all(s.people[0].clip != 'proc_sit' for s in specs)  # would sit on air
    split_of = {c.name: c.split for c in clips}
    for empty, furnished in zip(specs[::2], specs[1::2]):
        for spec in (empty, furnished):
            m = NAME.match(spec.name)
            assert m, spec.name
            a = spec.attributes
            assert (m[1], m[4], m[5], int(m[6]), m[7]) == (
                a['split'], spec.sensor, spec.room, len(spec.people), a['camera'])
            assert a['room'] == spec.room and a['interaction'] == spec.interaction == 'none'
            assert a['pair'] == [empty.name, furnished.name]
            assert spec.furnish == 'beside' and spec.suite == 'rooms'
            assert {split_of[p.clip] for p in spec.people} == {a['split']}
        assert (empty.room, furnished.room) == ('empty', 'furnished')
        # Everything but the room is shared.
        assert dataclasses.replace(empty, name='', room='furnished', attributes={}) == \
            dataclasses.replace(furnished, name='', attributes={})
        assert {k: v for k, v in empty.attributes.items() if k != 'room'} == \
            {k: v for k, v in furnished.attributes.items() if k != 'room'}
    assert {s.attributes['split'] for s in specs} == {'dev', 'test'}
    pans = [s for s in specs if s.attributes['camera'] == 'pan']
    static = [s for s in specs if s.attributes['camera'] == 'static']
    still = [s for s in static if s.attributes['motion'] == 'still']
    assert len(pans) == 4 and len(static) == 12 and len(still) == 4
    assert {s.attributes['split'] for s in still} == {'dev', 'test'}
    assert all(s.pan is None and 'pan_s' not in s.attributes for s in static)
    assert all(s.frames == QUICK_PAIR_FRAMES for s in static if s not in still)
    assert all(s.frames == 90 and s.name.endswith('-static-still-breathing3s') for s in still)
    for s in pans:
        assert s.frames == QUICK_PAN_FRAMES and s.people[0].view.kind in ('front', 'side', 'back')
        assert 20 <= abs(s.pan.yaw_deg) <= 30 and s.pan.start_s == QUICK_PAN_START_S
        assert s.attributes['pan_s'] == [s.pan.start_s, s.pan.end_s]
        assert s.pan.end_s * 30 < s.frames  # the camera is still again before the end


def test_committed_catalogue_gives_the_quick_suite():
    from endeff_ros.synth.mocap.catalogue import load_clips

    specs = rooms_specs(load_clips(committed_only=True), quick=True)
    assert len(specs) == 16 and {s.attributes['split'] for s in specs} == {'dev', 'test'}
    assert all(s.people[0].clip.startswith('deepmimic/') for s in specs)


def test_a_pair_renders_the_same_person_and_only_adds_furniture(clips, specs):
    byname = {c.name: c for c in clips}
    empty, furnished = (dataclasses.replace(s, frames=4, sensor='kinect_v2')
                        for s in specs[:2])
    ren_e, ren_f = BagRenderer(empty, byname), BagRenderer(furnished, byname)
    assert ren_e.clutter == [] and len(ren_f.clutter) >= 2
    box = lambda d: np.isfinite(d) & (d < 4.3)  # noqa: E731  where room.scatter places pieces
    for fe, ff in zip(ren_e.frames(), ren_f.frames(), strict=True):
        assert (fe.stamp_ns, fe.color_stamp_ns) == (ff.stamp_ns, ff.color_stamp_ns)
        np.testing.assert_array_equal(fe.gt, ff.gt)
        np.testing.assert_array_equal(fe.gt_ids, ff.gt_ids)
        assert len(fe.gt) == 5
        # Noise-free views: the person's pixels and depths are the same in both rooms (no
        # piece hides any of them); the furnished room adds furniture pixels elsewhere.
        ent, _ = ren_e.entity(fe.index)
        ideal_e = render(ent, ren_e.camera, ren_e.static)
        ideal_f = render(ent, ren_f.camera, ren_f.static)
        person = ideal_e.owner >= 0
        assert person.sum() > 500
        np.testing.assert_array_equal(ideal_f.owner >= 0, person)
        np.testing.assert_array_equal(ideal_f.z[person], ideal_e.z[person])
        np.testing.assert_array_equal(ideal_f.gt_visible, ideal_e.gt_visible)
        assert (ideal_e.owner == STATIC).sum() == 0 and (ideal_f.owner == STATIC).sum() > 2000
        # As sensed (the noise differs: the sensor models draw per edge pixel): many more
        # readings inside the foreground box.
        assert (fe.depth is None) == (ff.depth is None)
        if fe.depth is not None:
            assert box(ff.depth).sum() > box(fe.depth).sum() + 2000


def test_furniture_finds_room_beside_two_people_walking_across():
    """Two walks across the whole view at 1.4 and 2.25 m: the lines of sight to them leave no
    place near them, so the pieces go deeper into the foreground box; they still hide no one."""
    walk = walk_clip(90, 1.3, 'walk_x')
    people = (PersonSpec('walk_x', 0, BodyStyle(), View('across', 1.4, 1.2), 1),
              PersonSpec('walk_x', 0, BodyStyle(), View('across', 2.25, 1.2, side_sign=-1), 2))
    spec = BagSpec('two', people, 90, 'furnished', 'none', 'kinect_v2', 7, {},
                   furnish='beside')
    ren = BagRenderer(spec, {'walk_x': walk})
    assert len(ren.clutter) >= 2
    seen = 0
    for index in (0, 30, 60, 89):
        ent, _ = ren.entity(index)
        bare, room = render(ent, ren.camera), render(ent, ren.camera, ren.static)
        person = bare.owner >= 0
        np.testing.assert_array_equal(room.owner >= 0, person)
        np.testing.assert_array_equal(room.z[person], bare.z[person])
        seen += int((room.owner == STATIC).sum())
    assert seen > 4000


def _still_spec(pan: Pan | None, frames: int = 16) -> tuple[BagSpec, dict]:
    """One person standing still (the first pose of a walk held), seen from the front."""
    walk = walk_clip(30)
    still = MotionClip('still', 'procedural', 'other', 'dev', 30.0,
                       np.repeat(walk.positions[:1], 30, axis=0))
    view = View('front', 2.5, 1.3)
    spec = BagSpec('still', (PersonSpec('still', 0, BodyStyle(), view, 3),), frames,
                   'furnished', 'none', 'kinect_v2', 5, {}, furnish='beside', pan=pan)
    return spec, {'still': still}


def test_the_pan_moves_the_camera_between_its_stated_times_only():
    pan = Pan(0.1, 0.3, 24.0)  # frames 3 to 12 of 16
    spec, clips = _still_spec(pan)
    ren = BagRenderer(spec, clips)
    frames = list(ren.frames())
    details = ren.details()['pan']
    t0, t1 = details['start_stamp_ns'], details['end_stamp_ns']
    assert (t0, t1) == (T0_NS + 3 * PERIOD_NS, T0_NS + 12 * PERIOD_NS)
    assert details['yaw_deg'] == 24.0
    first, last = frames[0].gt, frames[-1].gt
    for f in frames:
        if f.stamp_ns <= t0:
            np.testing.assert_array_equal(f.gt, first)
        elif f.stamp_ns >= t1:
            np.testing.assert_array_equal(f.gt, last)
        else:  # moving: away from both ends, and from the previous frame
            assert np.abs(f.gt - first).max() > 1e-3 and np.abs(f.gt - last).max() > 1e-3
    moved = [np.abs(b.gt - a.gt).max() > 1e-4 for a, b in zip(frames, frames[1:])]
    assert moved == [3 <= k < 12 for k in range(15)]
    # The still person's ground truth turns with the camera: from the first to the last frame
    # by the rotation between the two camera poses, which is 24 degrees about the vertical.
    r0, r1 = ren.camera_at(0).rotation, ren.camera_at(15).rotation
    np.testing.assert_allclose(last, first @ (r1 @ r0.T).T, atol=1e-9)
    up = r0 @ np.array([0.0, 1.0, 0.0])
    turn = r1 @ r0.T
    angle = np.degrees(np.arccos((np.trace(turn) - 1) / 2))
    assert angle == pytest.approx(24.0, abs=1e-6)
    np.testing.assert_allclose(turn @ up, up, atol=1e-12)  # about the scene's vertical
    # The person the camera was aimed at stays in view (all five ends listed in every frame).
    assert all(len(f.gt) == 5 for f in frames)


def test_a_static_bag_keeps_its_camera():
    spec, clips = _still_spec(None, frames=4)
    ren = BagRenderer(spec, clips)
    frames = list(ren.frames())
    assert all(ren.camera_at(i) == ren.camera for i in range(4)) and ren.camera.yaw == 0.0
    for f in frames[1:]:
        np.testing.assert_array_equal(f.gt, frames[0].gt)
    assert 'pan' not in ren.details()


def test_bad_pan_is_a_clear_error():
    with pytest.raises(ValueError, match='duration_s must be > 0'):
        Pan(1.0, 0.0, 20.0)
    with pytest.raises(ValueError, match='yaw_deg'):
        Pan(1.0, 0.5, 120.0)
    spec, _ = _still_spec(None)
    with pytest.raises(ValueError, match='furnish must be one of'):
        dataclasses.replace(spec, furnish='everywhere')


def test_bag_metadata_holds_the_pair_and_the_pan(clips, specs, tmp_path):
    byname = {c.name: c for c in clips}
    spec = dataclasses.replace(next(s for s in specs if s.pan is not None), frames=3)
    out = write_bag(spec, byname, tmp_path)
    meta = yaml.safe_load((tmp_path / 'mcap' / spec.name / 'metadata.yaml').read_text())
    custom = meta['rosbag2_bagfile_information']['custom_data']
    attrs = json.loads(custom[ATTRIBUTES_KEY])
    details = json.loads(custom[DETAILS_KEY])
    assert attrs == {k: v for k, v in out.items() if k != 'frames'}
    assert attrs['camera'] == 'pan' and attrs['room'] == spec.room
    assert attrs['pair'] == spec.attributes['pair'] and spec.name in attrs['pair']
    assert attrs['pan_s'] == [spec.pan.start_s, spec.pan.end_s]
    assert details['suite'] == 'rooms' and details['pan']['yaw_deg'] == spec.pan.yaw_deg


def _cli_args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    synth_cli.add_arguments(parser)
    return parser.parse_args(['--suite', 'rooms', '--quick', *argv])


def test_cli_lists_the_rooms_suite(capsys):
    assert synth_cli.run(_cli_args('--list', '--only', '*-pan')) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[-1].startswith('4 bags')
    for line in lines[:-1]:
        name, attrs = line.split(' ', 1)
        assert NAME.match(name) and json.loads(attrs)['camera'] == 'pan'
    assert synth_cli.run(_cli_args('--list', '--max-seconds', '3')) == 2
    assert '--max-seconds' in capsys.readouterr().err
    assert synth_cli.run(_cli_args('--list', '--only', 'nothing*')) == 2
    assert 'rooms suite' in capsys.readouterr().err
