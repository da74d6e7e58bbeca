"""Mocap suite: the spec list, attributes in the rosbag2 metadata, and a tiny end-to-end run
written and read back with the project's bag reader."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import yaml
from rosbags.highlevel import AnyReader

from endeff_ros.attributes import ATTRIBUTES_KEY, custom_data, parse_attributes
from endeff_ros.bag.reader import read_frames
from endeff_ros.synth import cli as synth_cli
from endeff_ros.synth.proc_clips import sit_clip, walk_clip, wave_clip
from endeff_ros.synth.sensors import SENSORS
from endeff_ros.synth.mocap.clip import JOINT_INDEX
from endeff_ros.synth.skeleton_body import scale_to_height
from endeff_ros.synth.suite import (
    DETAILS_KEY,
    QUICK_FRAMES,
    SWAY_M,
    BagRenderer,
    area_pieces,
    draw_spec,
    fit_activity_area,
    resampled,
    suite_specs,
    write_bag,
)
from endeff_ros.synth.views import AREA_HALF_WIDTH_M, FARTHEST_M, NEAREST_M, View, place

KEYS = {'source', 'family', 'split', 'view', 'camera_height_m', 'distance_m', 'sensor', 'room',
        'people', 'truncated'}


@pytest.fixture(scope='module')
def clips():
    return [walk_clip(60, name='walk_a'), walk_clip(60, 1.0, 'walk_b', 'test'),
            walk_clip(45, 1.5, 'walk_c', 'test'), sit_clip(60), wave_clip(40),
            wave_clip(40, name='wave_b', split='dev')]


def test_quick_spec_list(clips):
    specs = suite_specs(clips, quick=True)
    assert len(specs) >= 40
    assert len({s.name for s in specs}) == len(specs)
    assert {s.attributes['split'] for s in specs} == {'dev', 'test'}
    assert len({s.sensor for s in specs}) >= 3
    assert {s.attributes['view'] for s in specs} == {'front', 'side', 'back', 'across',
                                                     'towards'}
    assert {s.room for s in specs} == {'empty', 'furnished', 'wall'}
    assert {len(s.people) for s in specs} == {1, 2, 3}
    for s in specs:
        assert s.frames == QUICK_FRAMES
        assert s.name.startswith(s.attributes['split'] + '__')
        assert KEYS - {'truncated'} <= set(s.attributes)
        assert 1.2 <= s.attributes['distance_m'] <= 5.0
        assert 0.6 <= s.attributes['camera_height_m'] <= 2.2
        assert all(p.body.child or 1.5 <= p.body.height_m <= 1.95 for p in s.people)
        # No clip of the other split in a bag (people of a bag share the split).
        split = {c.name: c.split for c in clips}
        assert {split[p.clip] for p in s.people} == {s.attributes['split']}
    sit = [s for s in specs if s.people[0].clip == 'proc_sit']
    assert sit and all(s.interaction == 'sit' for s in sit)
    assert specs == suite_specs(clips, quick=True)  # deterministic
    assert specs != suite_specs(clips, quick=True, seed=1)


def test_full_spec_list_covers_every_clip(clips):
    specs = suite_specs(clips, max_s=1.5)
    assert {c.name for c in clips} <= {s.people[0].clip for s in specs}
    longest = {c.name: len(c.positions) for c in clips}
    for s in specs:
        assert s.frames == min(longest[s.people[0].clip], 45)
    assert max(s.frames for s in suite_specs(clips)) == 60  # whole clips under FULL_MAX_S
    with pytest.raises(ValueError, match='max_s'):
        suite_specs(clips, max_s=0)


def test_committed_catalogue_gives_a_quick_suite():
    from endeff_ros.synth.mocap.catalogue import load_clips

    specs = suite_specs(load_clips(committed_only=True), quick=True)
    assert len(specs) >= 40
    assert {s.attributes['split'] for s in specs} == {'dev', 'test'}
    assert len({s.sensor for s in specs}) >= 3


def test_only_patterns(clips):
    specs = suite_specs(clips, quick=True)
    dev = synth_cli.select_specs(specs, 'dev__*')
    assert dev and all(s.attributes['split'] == 'dev' for s in dev)
    both = synth_cli.select_specs(specs, 'dev__*,*-d435-*')
    assert len(both) > len(dev)
    with pytest.raises(ValueError, match='nope'):
        synth_cli.select_specs(specs, 'nope*')


def _small(specs, **want):
    for s in specs:
        if all(s.attributes.get(k) == v for k, v in want.items()):
            return dataclasses.replace(s, frames=5)
    raise AssertionError(want)


def test_bags_end_to_end(clips, tmp_path):
    specs = suite_specs(clips, quick=True)
    byname = {c.name: c for c in clips}
    chosen = [_small(specs, people=2), _small(specs, sensor='kinect_v2', people=1),
              _small(specs, room='furnished', people=1)]
    for spec in chosen:
        out = write_bag(spec, byname, tmp_path)
        assert out['frames'] == 5
        bag = tmp_path / 'mcap' / spec.name
        # Attributes in the metadata, read back two ways.
        meta = yaml.safe_load((bag / 'metadata.yaml').read_text())
        raw = meta['rosbag2_bagfile_information']['custom_data']
        with AnyReader([bag]) as reader:
            attrs, warning = parse_attributes(custom_data(reader), spec.name)
            details = json.loads(custom_data(reader)[DETAILS_KEY])
        assert warning is None and KEYS <= set(attrs)
        assert json.loads(raw[ATTRIBUTES_KEY]) == attrs
        assert attrs == {k: v for k, v in out.items() if k != 'frames'}
        assert attrs['sensor'] == spec.sensor and attrs['people'] == len(spec.people)
        assert details['people'][0]['clip'] == spec.people[0].clip
        if spec.room == 'furnished':
            assert attrs['clutter']
        # Frames through the project's reader: size and intrinsics of the sensor, ground
        # truth of every person (5 ids each) equal to the renderer's.
        intr = SENSORS[spec.sensor].intrinsics
        expect = {f.stamp_ns: f for f in BagRenderer(spec, byname).frames()}
        n = 0
        for frame, gt in read_frames(bag):
            assert frame.depth.shape == (intr.height, intr.width)
            assert (frame.intrinsics.fx, frame.intrinsics.cx) == (intr.fx, intr.cx)
            ref = expect[frame.stamp_ns]
            assert gt is not None and len(gt) == len(ref.gt)
            np.testing.assert_allclose(np.asarray(gt)[:, :3], ref.gt, atol=1e-5)
            assert len(ref.gt_ids) in (5 * k for k in range(1, len(spec.people) + 1))
            np.testing.assert_array_equal(np.isfinite(frame.depth), np.isfinite(ref.depth))
            np.testing.assert_allclose(frame.depth[np.isfinite(frame.depth)],
                                       ref.depth[np.isfinite(ref.depth)], atol=1e-6)
            n += 1
        assert n >= 3  # a dropped frame or two at most


@pytest.mark.parametrize('sensor', ['d435', 'kinect_v2'])
def test_visible_ground_truth_lies_just_behind_the_depth_surface(sensor):
    """Depth and ground truth share the optical frame of a rolled, tilted camera: a visible
    end-effector's depth reading is its part's surface, 0-12 cm in front of its centre."""
    from endeff_ros.synth.skeleton_body import BodyStyle
    from endeff_ros.synth.suite import BagSpec, PersonSpec
    from endeff_ros.synth.views import View

    clip = wave_clip(30)
    view = View('front', 2.2, 1.7, tilt_deg=4.0, roll_deg=12.0)
    spec = BagSpec('r', (PersonSpec(clip.name, 0, BodyStyle(), view, 2),), 3, 'empty',
                   'none', sensor, 11, {})
    intr = SENSORS[sensor].intrinsics
    checked = 0
    for f in BagRenderer(spec, {clip.name: clip}).frames():
        if f.depth is None:
            continue
        uv = intr.project(f.gt)
        for (u, v), p, vis in zip(uv, f.gt, f.gt_visible):
            if not vis:
                continue
            ui, vi = int(round(u)), int(round(v))
            win = f.depth[vi - 1:vi + 2, ui - 1:ui + 2]
            gap = p[2] - np.nanmin(win)
            assert -0.02 < gap < 0.12
            checked += 1
    assert checked >= 6


def test_a_sit_clip_that_does_not_sit_gets_no_chair():
    from endeff_ros.synth.mocap.clip import MotionClip

    walk = walk_clip(60)
    perch = MotionClip('perch', 'procedural', 'sit', 'dev', 30.0, walk.positions)
    specs = suite_specs([perch, sit_clip(60, split='test')], quick=True)
    assert all(s.interaction != 'sit' for s in specs if s.people[0].clip == 'perch')
    assert all(s.interaction == 'sit' for s in specs if s.people[0].clip == 'proc_sit')


def _cli_args(**kw):
    import argparse

    parser = argparse.ArgumentParser()
    synth_cli.add_arguments(parser)
    argv = ['--suite', 'mocap', '--quick']
    for k, v in kw.items():
        argv += [f'--{k}'] if v is True else [f'--{k}', str(v)]
    return parser.parse_args(argv)


def test_cli_lists_and_reports_a_failed_bag(tmp_path, capsys):
    assert synth_cli.run(_cli_args(list=True, only='test__*')) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-1].startswith('24 bags') and all(line.startswith('test__') for line in out[:-1])
    blocked = tmp_path / 'out'
    (blocked / 'mcap').parent.mkdir()
    (blocked / 'mcap').write_text('not a folder')
    assert synth_cli.run(_cli_args(out=blocked, only='*__000-*', jobs=1)) == 1
    err = capsys.readouterr().err
    assert '__000-' in err and 'failed' in err
    assert synth_cli.run(_cli_args(list=True, only='nothing*')) == 2


def test_bad_spec_is_a_clear_error():
    from endeff_ros.synth.skeleton_body import BodyStyle
    from endeff_ros.synth.suite import BagSpec, PersonSpec
    from endeff_ros.synth.views import View

    person = PersonSpec('proc_wave', 0, BodyStyle(), View('front', 2.0, 1.2), 1)
    with pytest.raises(ValueError, match="sensor must be one of .*'kinect_v3'"):
        BagSpec('x', (person,), 5, 'empty', 'none', 'kinect_v3', 1)
    with pytest.raises(ValueError, match='room must be'):
        BagSpec('x', (person,), 5, 'garden', 'none', 'd435', 1)
    with pytest.raises(KeyError, match='proc_wave'):
        BagRenderer(BagSpec('x', (person,), 5, 'empty', 'none', 'd435', 1), {})


def _first_pelvis(spec, clip):
    """Placed pelvis (T, 3) of the first person of ``spec`` as the renderer places it."""
    p = spec.people[0]
    full = scale_to_height(resampled(clip), p.body.height_m)
    seg = full[p.start:p.start + spec.frames]
    seg = np.concatenate([seg, np.repeat(seg[-1:], spec.frames - len(seg), 0)])
    return place(seg, p.view)[0][:, JOINT_INDEX['pelvis']]


def _spec_for(clip, view, frames):
    rng = np.random.default_rng(0)
    base = draw_spec(1, clip, [clip], {clip.name: resampled(clip)}, frames, 1, rng, False)
    return dataclasses.replace(base, frames=frames, people=(
        dataclasses.replace(base.people[0], start=0, view=view),))


def _inside(pelvis):
    depth = -pelvis[:, 2]
    return ((np.abs(pelvis[:, 0]) <= AREA_HALF_WIDTH_M + 1e-6)
            & (depth >= NEAREST_M - 1e-6) & (depth <= FARTHEST_M + 1e-6))


@pytest.mark.parametrize('kind', ['front', 'back', 'across'])
def test_a_long_walk_becomes_pieces_inside_the_activity_area(kind):
    # 6 s at 1.3 m/s: 7.8 m of travel, which neither the area's 3 m of depth nor its 2.5 m of
    # width holds. Before the fit, part of the walk lies outside the area.
    clip = walk_clip(180, name='long_walk')
    spec = _spec_for(clip, View(kind, 2.5, 1.2), 180)
    assert not _inside(_first_pelvis(spec, clip)).all()
    pieces = area_pieces(spec, resampled(clip))
    assert len(pieces) >= 2
    spans = sorted((p.people[0].start, p.people[0].start + p.frames) for p in pieces)
    for (_, end), (start, _) in zip(spans, spans[1:]):
        assert start >= end  # the pieces do not overlap
    assert all(a >= 0 and b <= 180 for a, b in spans)
    for piece in pieces:
        assert piece.frames >= 30
        assert _inside(_first_pelvis(piece, clip)).all(), (kind, piece.people[0].start)
    # The pieces keep most of the walk (only rests shorter than a second are left out).
    assert sum(p.frames for p in pieces) >= 180 - 2 * 30


def test_a_border_cut_view_of_a_wide_sensor_is_brought_into_the_area():
    clip = wave_clip(60)
    spec = _spec_for(clip, View('front', 3.3, 1.2, offset_x_m=2.5), 60)
    fitted = fit_activity_area(spec, resampled(clip))
    view = fitted.people[0].view
    assert view.offset_x_m == pytest.approx(AREA_HALF_WIDTH_M - SWAY_M)
    # Nearer in proportion, so that the person is still cut at the image border.
    assert view.distance_m == pytest.approx(3.3 * (AREA_HALF_WIDTH_M - SWAY_M) / 2.5, abs=0.01)
    assert fitted.attributes['distance_m'] == view.distance_m
    assert _inside(_first_pelvis(fitted, clip)).all()


def test_a_person_inside_the_area_is_left_as_drawn():
    clip = wave_clip(60)
    spec = _spec_for(clip, View('side', 2.5, 1.2), 60)
    assert fit_activity_area(spec, resampled(clip)) == spec
    assert area_pieces(spec, resampled(clip)) == [spec]


def test_full_suite_bags_keep_the_first_person_in_the_area(clips):
    by_name = {c.name: c for c in clips}
    specs = suite_specs(clips)
    assert len({s.name for s in specs}) == len(specs)
    for s in specs:
        assert _inside(_first_pelvis(s, by_name[s.people[0].clip])).mean() >= 0.9, s.name
