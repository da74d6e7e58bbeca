"""Mocap suite: the depth sensor models (structured light, time of flight, active stereo) and
furniture (in the depth image, never ground truth)."""

from __future__ import annotations

import numpy as np
import pytest

from endeff_ros.synth.render import STATIC, Camera, background, render, static_layer
from endeff_ros.synth.room import BUILDERS, background_entity, scatter
from endeff_ros.synth.sensors import SENSORS, sensor_depth
from endeff_ros.synth.shapes import box


def _step_scene(model, near: float = 1.5, far: float = 3.0):
    """A wide box (front face at ``near`` m) in front of a wall at ``far`` m, camera level."""
    cam = Camera(model.intrinsics, height=1.2, pitch=0.0, wall_z=-far)
    slab = box([0.3, 1.2, -near - 0.1], np.eye(3), [0.5, 0.5, 0.1], (0.6, 0.6, 0.6), 1, 'slab')
    return render(background_entity([slab]), cam)


def test_tof_flying_pixels_at_a_step_edge():
    model = SENSORS['kinect_v2']
    ren = _step_scene(model)
    depth = sensor_depth(ren, model, np.random.default_rng(3))
    rows = np.nonzero((ren.owner == 0).any(1))[0][5:-5]  # slab and wall only, no floor
    between = np.zeros_like(depth, bool)
    between[rows] = np.isfinite(depth[rows]) & (depth[rows] > 1.65) & (depth[rows] < 2.8)
    v, u = np.nonzero(between)
    assert len(v) > 50
    # They sit at the slab's silhouette: within 3 px of a pixel whose ideal depth jumps.
    z = ren.z
    jump = np.zeros_like(z, bool)
    jump[:, 1:] |= np.abs(np.diff(z, axis=1)) > 0.5
    jump[1:, :] |= np.abs(np.diff(z, axis=0)) > 0.5
    near_edge = np.zeros_like(jump)
    for dv in range(-3, 4):
        for du in range(-3, 4):
            near_edge |= np.roll(np.roll(jump, dv, 0), du, 1)
    assert near_edge[v, u].mean() > 0.95
    # Structured light has far fewer flying pixels on the same edge.
    sl_ren = _step_scene(SENSORS['kinect_v1'])
    sl = sensor_depth(sl_ren, SENSORS['kinect_v1'], np.random.default_rng(3))[
        np.nonzero((sl_ren.owner == 0).any(1))[0][5:-5]]
    assert (np.isfinite(sl) & (sl > 1.65) & (sl < 2.8)).sum() < 0.6 * len(v)


def test_tof_drops_dark_surfaces():
    model = SENSORS['azure_nfov']
    cam = Camera(model.intrinsics, height=1.2, pitch=0.0, wall_z=-3.5)
    dark = box([0.0, 1.2, -2.2], np.eye(3), [0.3, 0.3, 0.05], (0.03, 0.03, 0.03), 1, 'dark')
    light = box([0.0, 1.2, -2.2], np.eye(3), [0.3, 0.3, 0.05], (0.9, 0.9, 0.9), 1, 'light')
    rng = np.random.default_rng(0)
    miss = []
    for b in (dark, light):
        ren = render(background_entity([b]), cam)
        d = sensor_depth(ren, model, rng)
        miss.append(np.isnan(d[ren.owner == 0]).mean())
    assert miss[0] > 0.25 and miss[1] < 0.05 and miss[0] > 5 * miss[1]


def _plane_error(model, z: float, seed: int) -> float:
    cam = Camera(model.intrinsics, height=1.2, pitch=0.0, wall_z=-z)
    ren = render(background_entity([]), cam)
    d = sensor_depth(ren, model, np.random.default_rng(seed))
    h, w = d.shape
    patch = np.s_[h // 2 - 40:h // 2 - 10, w // 2 - 60:w // 2 + 60]
    err = (d - ren.z)[patch]
    return float(np.nanstd(err))


@pytest.mark.parametrize('name', ['d435', 'd455'])
def test_stereo_noise_grows_with_z_squared(name):
    model = SENSORS[name]
    near = np.mean([_plane_error(model, 1.5, s) for s in range(3)])
    far = np.mean([_plane_error(model, 3.0, s) for s in range(3)])
    assert 2.5 < far / near < 6.0  # 4 for sigma ~ z^2
    # Expected size: z^2 sigma_d / (f B) with the correlated part, within a factor of 2.
    expect = 1.5 ** 2 * model.disparity_sigma_px / (model.intrinsics.fx * model.baseline_m)
    assert 0.5 * expect < near < 2.5 * expect


def test_stereo_occlusion_holes_left_of_near_edges():
    model = SENSORS['d435']
    ren = _step_scene(model, near=1.2, far=3.0)
    depth = sensor_depth(ren, model, np.random.default_rng(1))
    rows = np.nonzero((ren.owner == 0).any(1))[0]
    row = rows[len(rows) // 2]
    left = int(np.nonzero(ren.owner[row] == 0)[0].min())  # slab's left edge in this row
    fb = model.intrinsics.fx * model.baseline_m
    width = fb * (1 / 1.2 - 1 / 3.0)  # px the second imager cannot see
    strip = np.isnan(depth[rows[5:-5], left - int(width) + 2:left - 2])
    assert strip.mean() > 0.9
    beyond = np.isnan(depth[rows[5:-5], left - int(width) - 30:left - int(width) - 6])
    assert beyond.mean() < 0.2
    assert width > 15  # the test scene has a real shadow


@pytest.mark.parametrize('name', sorted(SENSORS))
def test_resolution_and_intrinsics(name):
    model = SENSORS[name]
    intr = model.intrinsics
    cam = Camera(intr, height=1.2, pitch=0.1, wall_z=-2.5)
    ren = render(background_entity([]), cam)
    depth = sensor_depth(ren, model, np.random.default_rng(0))
    assert depth.shape == (intr.height, intr.width) and depth.dtype == np.float32
    hfov = np.rad2deg(2 * np.arctan(intr.width / (2 * intr.fx)))
    assert 55 < hfov < 95
    assert abs(intr.cx - (intr.width - 1) / 2) < 2 and abs(intr.cy - (intr.height - 1) / 2) < 2
    good = np.isfinite(depth)
    assert good.mean() > 0.6
    assert np.nanmin(depth) >= model.z_min and np.nanmax(depth) <= model.z_max
    expected = {'kinect_v1': (640, 480), 'xtion': (640, 480), 'azure_nfov': (640, 576),
                'kinect_v2': (512, 424), 'd435': (848, 480), 'd455': (1280, 720)}[name]
    assert (intr.width, intr.height) == expected


def test_sensor_rejects_a_render_of_another_size():
    ren = render(background_entity([]), Camera(SENSORS['kinect_v1'].intrinsics))
    with pytest.raises(ValueError, match='d435'):
        sensor_depth(ren, SENSORS['d435'], np.random.default_rng(0))


def test_furniture_is_in_depth_but_never_ground_truth():
    model = SENSORS['kinect_v1']
    cam = Camera(model.intrinsics, height=1.3, pitch=0.2)
    pieces = [BUILDERS[k](x, -2.6, 0.2) for k, x in zip(('table', 'shelf', 'lamp', 'boxes'),
                                                          (-1.0, 0.0, 0.7, 1.2))]
    ent = background_entity([p for ps in pieces for p in ps])
    assert len(ent.gt) == 0 and len(ent.gt_ids) == 0
    layer = static_layer(ent, cam)
    seen = layer.owner == STATIC
    assert seen.mean() > 0.05
    bg = background(cam)
    assert (layer.z[seen] < bg.z[seen] - 0.02).mean() > 0.9  # in front of floor and wall
    ren = render(background_entity([]), cam, layer)
    assert len(ren.gt) == 0 and (ren.owner[seen] == STATIC).all()
    depth = sensor_depth(ren, model, np.random.default_rng(2))
    assert np.isfinite(depth[seen]).mean() > 0.8
    np.testing.assert_allclose(np.nanmedian(np.abs(depth[seen] - ren.z[seen])), 0, atol=0.02)


def test_scatter_keeps_walkways_clear():
    rng = np.random.default_rng(4)
    path = np.stack([np.linspace(-1.5, 1.5, 30), np.full(30, -2.5)], 1)
    placed = scatter(rng, path, 6, (-1.5, 1.5), (-4.0, -1.0))
    assert placed
    for _kind, prims in placed:
        c = np.mean([p.center for p in prims], 0)
        assert np.min(np.hypot(path[:, 0] - c[0], path[:, 1] - c[2])) > 0.45
