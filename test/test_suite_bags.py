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
from endeff_ros.synth.cases import suite_specs
from endeff_ros.synth.proc_clips import sit_clip, walk_clip, wave_clip
from endeff_ros.synth.sensors import SENSORS
from endeff_ros.synth.suite import (
    DETAILS_KEY,
    QUICK_FRAMES,
    BagRenderer,
    write_bag,
)

KEYS = {'source', 'family', 'split', 'view', 'camera_height_m', 'distance_m', 'sensor', 'room',
        'people', 'truncated'}


@pytest.fixture(scope='module')
def clips():
    return [walk_clip(60, name='walk_a'), walk_clip(60, 1.0, 'walk_b', 'test'),
            walk_clip(45, 1.5, 'walk_c', 'test'), sit_clip(60), wave_clip(40),
            wave_clip(40, name='wave_b', split='dev')]


def test_quick_spec_list(clips):
    every = suite_specs(clips, quick=True)
    specs = [s for s in every if s.attributes['case'] == 'segment']
    assert {s.attributes['motion'] for s in every} == {'active', 'still', 'slow'}
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
    assert every == suite_specs(clips, quick=True)  # deterministic
    assert every != suite_specs(clips, quick=True, seed=1)


def test_full_spec_list_covers_every_clip(clips):
    specs = [s for s in suite_specs(clips, max_s=1.5) if s.attributes['case'] == 'segment']
    assert {c.name for c in clips} <= {s.people[0].clip for s in specs}
    longest = {c.name: len(c.positions) for c in clips}
    for s in specs:
        assert s.frames == min(longest[s.people[0].clip], 45)
    assert max(s.frames for s in suite_specs(clips)
               if s.attributes['case'] == 'segment') == 60  # whole clips under FULL_MAX_S
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
    specs = [s for s in suite_specs([perch, sit_clip(60, split='test')], quick=True)
             if s.attributes['case'] == 'segment']
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
    assert out[-1].startswith('31 bags') and all(line.startswith('test__') for line in out[:-1])
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
