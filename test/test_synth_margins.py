"""Dead margins of registered depth: every sensor model of the mocap and rooms suites reads
nothing in its margins (0 in 16UC1), readings everywhere else are those of its twin without
margins, colour stays full-frame, and the paper suite keeps every pixel."""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
import pytest

from endeff_ros.synth import cli as synth_cli
from endeff_ros.synth.cases import suite_specs
from endeff_ros.synth.proc_clips import walk_clip, wave_clip
from endeff_ros.synth.render import Camera, render
from endeff_ros.synth.room import background_entity
from endeff_ros.synth.sensor import depth_to_mm
from endeff_ros.synth.sensors import SENSORS, DeadMargin, sensor_depth, without_margin
from endeff_ros.synth.suite import BagRenderer


def _room(model):
    """Wall 2.5 m ahead and floor: a surface behind every pixel, all within range."""
    cam = Camera(model.intrinsics, height=1.2, pitch=0.0, wall_z=-2.5)
    return render(background_entity([]), cam)


@pytest.mark.parametrize('name', sorted(SENSORS))
def test_depth_reads_nothing_in_the_margin_and_its_twin_reads_there(name):
    model = SENSORS[name]
    assert model.margin is not None
    intr = model.intrinsics
    dead = model.margin.mask(intr.width, intr.height)
    assert 0.03 < dead.mean() < 0.25  # a band, not the image
    ren = _room(model)
    depth = sensor_depth(ren, model, np.random.default_rng(5))
    mm = depth_to_mm(depth)
    assert (mm[dead] == 0).all()
    assert (mm[~dead] > 0).mean() > 0.8
    twin = sensor_depth(ren, without_margin(model), np.random.default_rng(5))
    assert np.isfinite(twin[dead]).mean() > 0.8
    np.testing.assert_array_equal(twin[~dead], depth[~dead])


def test_margin_shapes_at_the_models_resolutions():
    # Kinect v1 / Xtion at 640x480: rows 0-33 and 464-479, columns 0-40 and 605-639.
    for name in ('kinect_v1', 'xtion'):
        dead = SENSORS[name].margin.mask(640, 480)
        rows, cols = np.nonzero(~dead)
        assert (rows.min(), rows.max(), cols.min(), cols.max()) == (34, 463, 41, 604)
    # RealSense: one band on the left, 60-90 px at 848 wide, proportional at 1280.
    for name, width in (('d435', 848), ('d455', 1280)):
        intr = SENSORS[name].intrinsics
        dead = SENSORS[name].margin.mask(intr.width, intr.height)
        band = int(dead[intr.height // 2].sum())
        assert 60 * width / 848 <= band <= 90 * width / 848
        assert dead[:, :band].all() and not dead[:, band:].any()
    # Azure Kinect NFOV: the corners are cut, the middle of every side reads.
    dead = SENSORS['azure_nfov'].margin.mask(640, 576)
    assert dead[0, 0] and dead[0, -1] and dead[-1, 0] and dead[-1, -1]
    assert not dead[288, 0] and not dead[288, -1] and not dead[0, 320] and not dead[-1, 320]
    assert dead[0, :100].all() and not dead[0, 150:490].any()
    # Kinect v2 registered to colour: a band on either side.
    dead = SENSORS['kinect_v2'].margin.mask(512, 424)
    assert dead[:, :40].all() and dead[:, -40:].all() and not dead[:, 70:-70].any()
    with pytest.raises(ValueError, match='fractions'):
        DeadMargin(left=0.6)


@pytest.fixture(scope='module')
def clips():
    return [walk_clip(60, name='walk_a'), wave_clip(40, name='wave_a', split='dev')]


@pytest.mark.parametrize('sensor', ['kinect_v1', 'd435', 'azure_nfov'])
def test_a_bag_and_its_twin_without_margins(clips, sensor):
    spec = next(s for s in suite_specs(clips, quick=True) if len(s.people) == 1)
    spec = dataclasses.replace(spec, frames=3, sensor=sensor)
    twin = dataclasses.replace(spec, margins=False)
    byname = {c.name: c for c in clips}
    intr = SENSORS[sensor].intrinsics
    dead = SENSORS[sensor].margin.mask(intr.width, intr.height)
    ren, ren_twin = BagRenderer(spec, byname), BagRenderer(twin, byname)
    for f, g in zip(ren.frames(), ren_twin.frames(), strict=True):
        np.testing.assert_array_equal(f.gt, g.gt)
        if f.color is not None:  # colour is full-frame in both
            np.testing.assert_array_equal(f.color, g.color)
            assert f.color[dead].max() > 0
        if f.depth is None:
            continue
        assert not np.isfinite(f.depth[dead]).any()
        assert np.isfinite(g.depth[dead]).any()
        np.testing.assert_array_equal(f.depth[~dead], g.depth[~dead])
    assert ren.attributes()['margins'] is True and ren_twin.attributes()['margins'] is False


def test_the_suites_option_turns_the_margins_off(clips):
    assert all(s.margins and s.attributes['margins'] for s in suite_specs(clips, quick=True))
    off = suite_specs(clips, quick=True, margins=False)
    assert all(not s.margins and s.attributes['margins'] is False for s in off)
    assert [s.name for s in off] == [s.name for s in suite_specs(clips, quick=True)]
    parser = argparse.ArgumentParser()
    synth_cli.add_arguments(parser)
    args = parser.parse_args(['--suite', 'rooms', '--quick', '--no-margins'])
    assert all(not s.margins for s in synth_cli._suite_specs(args, clips))
    args = parser.parse_args(['--suite', 'mocap', '--quick'])
    assert all(s.margins for s in synth_cli._suite_specs(args, clips))


def test_the_paper_suite_reads_at_the_border():
    """The paper suite's structured-light model has no margins: its frames read in the band
    the Kinect v1 model leaves dead (its bags stay as they were)."""
    from endeff_ros.synth.frames import render_sequence

    frame = next(render_sequence('waving_one_hand', quick=True))
    dead = SENSORS['kinect_v1'].margin.mask(640, 480)
    assert np.isfinite(frame.depth[dead]).mean() > 0.8
