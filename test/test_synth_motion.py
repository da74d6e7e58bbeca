"""Still and slow people (synth/motion.py, synth/cases.py): the motion attribute and its eval
groups, a still person's ground truth and pixels, slowed clips, seated, leaving and arriving
people."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from endeff_ros.attributes import attribute_groups
from endeff_ros.synth import cli as synth_cli
from endeff_ros.synth.cases import MOCAP_FULL, MOCAP_QUICK, suite_specs
from endeff_ros.synth.mocap.catalogue import load_clips
from endeff_ros.synth.mocap.clip import JOINT_INDEX as J
from endeff_ros.synth.motion import MOTIONS, breathe, seat, stretch
from endeff_ros.synth.proc_clips import walk_clip, wave_clip
from endeff_ros.synth.render import render
from endeff_ros.synth.rooms_suite import rooms_specs
from endeff_ros.synth.suite import BagRenderer


@pytest.fixture(scope='module')
def committed():
    return load_clips(committed_only=True)


@pytest.fixture(scope='module')
def quick(committed):
    return suite_specs(committed, quick=True)


def _case(specs, case, split='test'):
    return next(s for s in specs if s.attributes['case'] == case
                and s.attributes['split'] == split)


def test_every_bag_says_how_it_moves_and_each_split_has_still_and_slow_bags(committed,
                                                                           quick):
    looped = load_clips(committed_only=True, loop_s=synth_cli.LOOP_S)
    for specs in (quick, suite_specs(looped), rooms_specs(committed, quick=True)):
        assert all(s.attributes['motion'] in MOTIONS for s in specs)
        for split in ('dev', 'test'):
            mine = [s for s in specs if s.attributes['split'] == split]
            assert {s.attributes['motion'] for s in mine} >= {'still', 'active'}
            # A split's clips stay in their split.
            split_of = {c.name: c.split for c in committed}
            assert {split_of[p.clip] for s in mine for p in s.people} == {split}
    for split in ('dev', 'test'):
        mine = [s for s in quick if s.attributes['split'] == split]
        assert {s.attributes['motion'] for s in mine} == set(MOTIONS)
        assert len([s for s in mine if s.attributes['case'] != 'segment']) == len(MOCAP_QUICK)
        assert all(s.frames == 90 for s in mine if s.attributes['case'] in
                   ('frozen', 'breathing', 'seated'))
    full = suite_specs(looped)
    for split in ('dev', 'test'):
        still = [s for s in full if s.attributes['split'] == split and
                 s.attributes['motion'] == 'still']
        assert max(s.frames for s in still) == 60 * 30 and min(s.frames for s in still) == 90
    cases = [s for s in full if s.attributes['case'] != 'segment']
    assert len(cases) == 2 * (len(MOCAP_FULL) - 1)  # no ReActIdle without the cache


def test_eval_groups_by_motion_and_older_bags_count_as_active():
    groups = attribute_groups([('old', {'view': 'side'}), ('still', {'motion': 'still'}),
                               ('slow', {'motion': 'slow', 'view': 'front'}),
                               ('no attributes', {})])
    assert groups['motion'] == {'motion=active': ['old'], 'motion=still': ['still'],
                                'motion=slow': ['slow']}


def test_a_frozen_person_keeps_their_ground_truth_and_pixels(committed, quick):
    spec = dataclasses.replace(_case(quick, 'frozen'), frames=6)
    byname = {c.name: c for c in committed}
    ren = BagRenderer(spec, byname)
    frames = list(ren.frames())
    assert all(len(f.gt) == 5 for f in frames)
    for f in frames[1:]:
        np.testing.assert_array_equal(f.gt, frames[0].gt)
    # Without sensor noise the body's depth pixels are the same in every frame.
    ideal = [render(ren.entity(i)[0], ren.camera, ren.static) for i in (0, 5)]
    person = ideal[0].owner >= 0
    assert person.sum() > 300
    np.testing.assert_array_equal(ideal[1].owner >= 0, person)
    np.testing.assert_array_equal(ideal[1].z[person], ideal[0].z[person])


def test_breathing_moves_a_few_millimetres(committed, quick):
    spec = _case(quick, 'breathing')
    joints = BagRenderer(spec, {c.name: c for c in committed}).joints[0]
    move = np.linalg.norm(joints - joints[0], axis=2)
    assert 0.002 < move.max() < 0.012
    assert move[:, [J['l_toe'], J['r_toe']]].max() < 0.001  # feet on the floor
    # Over a whole breath the chest rises and falls by about +-3 mm.
    pose = np.repeat(joints[:1], 150, 0)
    chest = breathe(pose, np.random.default_rng(1))[:, J['chest'], 1]
    assert 0.004 < chest.max() - chest.min() < 0.018


def test_a_slowed_clip_spans_factor_times_the_frames():
    seg = walk_clip(11).positions
    for factor in (10, 20):
        out = stretch(seg, factor, 10 * factor)
        assert out.shape == (10 * factor, 22, 3)
        np.testing.assert_allclose(out[::factor], seg[:10])
        step = np.linalg.norm(np.diff(out[:, J['l_wrist']], axis=0), axis=1).max()
        assert step < np.linalg.norm(np.diff(seg[:, J['l_wrist']], axis=0), axis=1).max()
    for row in MOCAP_FULL + MOCAP_QUICK:
        if row.case == 'slowed':
            assert row.factor in (10, 20)


def test_slowed_bags_span_factor_times_their_source(quick):
    slowed = [s for s in quick if s.attributes['case'] == 'slowed']
    assert {s.people[0].factor for s in slowed} == {10, 20}
    for s in slowed:
        source = next(r.source_frames for r in MOCAP_QUICK if r.factor == s.people[0].factor)
        assert s.frames == source * s.people[0].factor and s.attributes['motion'] == 'slow'


def test_seated_pose_bends_hips_and_knees_and_gets_a_chair(committed, quick):
    standing = wave_clip(2).positions[0]  # legs straight
    sat = seat(standing)
    for side in ('l', 'r'):
        hip, knee, ankle = (sat[J[f'{side}_{n}']] for n in ('hip', 'knee', 'ankle'))
        thigh, shin = knee - hip, ankle - knee
        assert abs(thigh[1]) < 0.01 and abs(np.linalg.norm(thigh[[0, 2]]) - 0.43) < 0.01
        assert np.linalg.norm(shin[[0, 2]]) < 0.01 and shin[1] == pytest.approx(-0.42)
        np.testing.assert_allclose(ankle, standing[J[f'{side}_ankle']], atol=1e-9)
    assert sat[J['pelvis'], 1] < standing[J['pelvis'], 1] - 0.35
    assert sat[J['head_top'], 1] - sat[J['pelvis'], 1] == pytest.approx(
        standing[J['head_top'], 1] - standing[J['pelvis'], 1])
    spec = _case(quick, 'seated')
    ren = BagRenderer(spec, {c.name: c for c in committed})
    assert spec.interaction == 'sit' and 'chair' in ren.clutter
    assert np.ptp(ren.joints[0], axis=0).max() < 0.02  # still, breathing


def _listed(ren, index):
    return bool(ren.entity(index)[1].any())


def test_a_person_who_stands_still_and_then_walks_out_of_view(committed, quick):
    spec = _case(quick, 'leaves')
    ren = BagRenderer(spec, {c.name: c for c in committed})
    hold = spec.people[0].hold
    pelvis = ren.joints[0][:, J['pelvis']]
    assert hold == 90 and spec.attributes['motion'] == 'still'
    assert np.linalg.norm(pelvis[:hold] - pelvis[0], axis=1).max() < 0.02  # sway
    assert np.linalg.norm(pelvis[-1] - pelvis[0]) > 1.0
    assert _listed(ren, 0) and _listed(ren, hold - 1) and not _listed(ren, spec.frames - 1)


def test_a_person_who_walks_in_and_stays_still(committed, quick):
    spec = _case(quick, 'arrives', 'dev')
    ren = BagRenderer(spec, {c.name: c for c in committed})
    hold = spec.people[0].hold
    pelvis = ren.joints[0][:, J['pelvis']]
    assert spec.frames - hold == 30
    assert np.linalg.norm(pelvis[hold:] - pelvis[-1], axis=1).max() < 0.02  # sway
    assert np.linalg.norm(pelvis[0] - pelvis[-1]) > 1.0
    assert not _listed(ren, 0) and _listed(ren, spec.frames - 1)
