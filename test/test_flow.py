"""Tests of the predict phase's optical flow and 3D scene flow (Section 5.1)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from endeff_ros.core.errors import InputError, ParameterError
from endeff_ros.core.flow import METHODS, FlowEstimator, propagate_points
from endeff_ros.core.types import Intrinsics
from tools.flow_eval import flow_benchmark, make_pair, texture

W, H = 640, 480
K = Intrinsics(fx=525.0, fy=525.0, cx=319.5, cy=239.5, width=W, height=H)


def _shifted_pair(du: float, dv: float, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A textured scene and the same scene translated by (du, dv) pixels (RGB uint8)."""
    rng = np.random.default_rng(seed)
    pad = 40
    canvas = texture(rng, H + 2 * pad, W + 2 * pad)
    shift = np.float32([[1, 0, du], [0, 1, dv]])
    moved = cv2.warpAffine(canvas, shift, (W + 2 * pad, H + 2 * pad), flags=cv2.INTER_LINEAR)
    prev = canvas[pad:pad + H, pad:pad + W].astype(np.uint8)
    cur = moved[pad:pad + H, pad:pad + W].astype(np.uint8)
    return prev, cur


def _constant_flow(du: float, dv: float) -> np.ndarray:
    flow = np.empty((H, W, 2), np.float32)
    flow[..., 0], flow[..., 1] = du, dv
    return flow


def _depth(value: float) -> np.ndarray:
    return np.full((H, W), value, np.float32)


def _at(u: float, v: float, z: float) -> np.ndarray:
    """(1, 3) point seen at pixel (u, v) at depth z."""
    return np.array([[(u - K.cx) * z / K.fx, (v - K.cy) * z / K.fy, z]])


def _moving_disc(radius: int, shift: tuple[int, int], flow: tuple[float, float],
                 depth: tuple[float, float], background: float,
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A disc centred at (320, 240) in front of a flat ``background`` moves by ``shift``
    pixels; the flow field says ``flow`` on the disc and 0 elsewhere. ``depth``: the disc's
    depth before and after. Returns (flow, previous depth, current depth)."""
    yy, xx = np.mgrid[0:H, 0:W]
    disc = (xx - 320) ** 2 + (yy - 240) ** 2 <= radius ** 2
    moved = (xx - 320 - shift[0]) ** 2 + (yy - 240 - shift[1]) ** 2 <= radius ** 2
    field = np.zeros((H, W, 2), np.float32)
    field[disc] = flow
    prev = np.where(disc, depth[0], background).astype(np.float32)
    cur = np.where(moved, depth[1], background).astype(np.float32)
    return field, prev, cur


# --- FlowEstimator -------------------------------------------------------------------------------

@pytest.mark.parametrize(('du', 'dv'), [(6.0, -3.0), (-2.5, 4.0), (12.0, 5.0)])
def test_default_method_recovers_a_translation(du: float, dv: float) -> None:
    prev, cur = _shifted_pair(du, dv)
    flow = FlowEstimator().flow(prev, cur)
    interior = flow[40:-40, 40:-40].reshape(-1, 2)
    median = np.median(interior, axis=0)
    assert median == pytest.approx([du, dv], abs=0.3)
    # Most pixels are right, not just the median.
    err = np.linalg.norm(interior - [du, dv], axis=1)
    assert np.mean(err < 1.0) > 0.9


def test_default_method_follows_a_blob_over_a_static_background() -> None:
    pair = make_pair('blob', 5.0, -3.0, 2.0, 1.0, seed=7)
    flow = FlowEstimator().flow(pair.prev, pair.cur)
    obj = cv2.erode(pair.obj.astype(np.uint8), np.ones((15, 15), np.uint8)).astype(bool)
    bg = pair.valid & ~cv2.dilate(pair.obj.astype(np.uint8), np.ones((31, 31), np.uint8),
                                  ).astype(bool)
    obj_err = np.linalg.norm(flow[obj] - pair.flow[obj], axis=1)
    assert np.median(obj_err) < 1.5
    assert np.median(np.linalg.norm(flow[bg], axis=1)) < 0.5  # the torso stays put


@pytest.mark.parametrize('method', METHODS)
@pytest.mark.parametrize('scale', [1.0, 0.5, 0.37])
def test_flow_shape_and_dtype(method: str, scale: float) -> None:
    rng = np.random.default_rng(0)
    prev = (texture(rng, 77, 101)).astype(np.uint8)
    cur = np.roll(prev, 2, axis=1)
    flow = FlowEstimator(method, scale=scale).flow(prev, cur)
    assert flow.shape == (77, 101, 2)
    assert flow.dtype == np.float32
    assert np.isfinite(flow).all()
    # Grayscale input gives the same result as RGB converted to grey.
    gray = FlowEstimator(method, scale=scale).flow(cv2.cvtColor(prev, cv2.COLOR_RGB2GRAY),
                                                   cv2.cvtColor(cur, cv2.COLOR_RGB2GRAY))
    np.testing.assert_allclose(gray, flow, atol=1e-4)


def test_scaled_flow_vectors_are_in_full_resolution_pixels() -> None:
    prev, cur = _shifted_pair(8.0, 0.0)
    for scale in (1.0, 0.5):
        flow = FlowEstimator('dis_fast', scale=scale).flow(prev, cur)
        assert np.median(flow[60:-60, 60:-60, 0]) == pytest.approx(8.0, abs=0.4)


def test_flow_rejects_bad_inputs() -> None:
    est = FlowEstimator()
    a = np.zeros((48, 64, 3), np.uint8)
    with pytest.raises(InputError, match='differ in size'):
        est.flow(a, np.zeros((48, 65, 3), np.uint8))
    with pytest.raises(InputError, match='uint8'):
        est.flow(a.astype(np.float32), a.astype(np.float32))
    with pytest.raises(InputError, match='RGB'):
        est.flow(np.zeros((48, 64, 4), np.uint8), np.zeros((48, 64, 4), np.uint8))
    with pytest.raises(InputError, match='too small'):
        est.flow(np.zeros((4, 4), np.uint8), np.zeros((4, 4), np.uint8))
    with pytest.raises(ParameterError, match='unknown optical flow method'):
        FlowEstimator('ldof')
    for scale in (0.0, -1.0, 1.5, float('nan'), True, '0.5'):
        with pytest.raises(ParameterError, match='scale'):
            FlowEstimator('dis', scale=scale)  # type: ignore[arg-type]


def test_flow_benchmark_table() -> None:
    threads = cv2.getNumThreads()
    result = flow_benchmark(repeats=1, seeds=1, configs=(('dis', 0.5), ('farneback', 0.5)),
                            cases=(('pan', 4.0, 2.0, 0.0, 1.0), ('blob_5px', 5.0, 2.0, 1.0, 1.0)))
    assert result['image'] == [640, 480]
    assert [r['method'] for r in result['rows']] == ['dis', 'farneback']
    for row in result['rows']:
        assert set(row) >= {'method', 'scale', 'epe_mean', 'epe_object', 'time_ms'}
        assert 0 <= row['epe_mean'] < 1.0  # sub-pixel on average over the image
        assert 0 <= row['epe_object'] < 3.0
        assert row['time_ms'] > 0
    assert cv2.getNumThreads() == threads  # the caller's thread count is restored


# --- propagate_points ----------------------------------------------------------------------------

def test_propagate_points_on_a_translating_textured_plane() -> None:
    """A fronto-parallel textured plane at 2 m moves by (+6 cm, -3 cm, +2 cm) in 3D."""
    z0, motion = 2.0, np.array([0.06, -0.03, 0.02])
    du, dv = K.fx * motion[0] / z0, K.fy * motion[1] / z0  # ~(15.75, -7.9) px
    prev, cur = _shifted_pair(du, dv, seed=11)
    flow = FlowEstimator().flow(prev, cur)
    points = np.array([[0.0, 0.0, z0], [-0.4, 0.2, z0], [0.5, -0.3, z0]])
    out, reliable = propagate_points(points, flow, _depth(z0), _depth(z0 + motion[2]), K)
    assert reliable.all()
    assert out.shape == (3, 3) and out.dtype == np.float64
    expected = points + motion
    # The image motion is that of the plane at z0, so x/y are exact up to the flow error and the
    # z change (1 %); a few cm is the brief's tolerance, we get well below that.
    np.testing.assert_allclose(out, expected, atol=0.02)


def test_propagate_points_with_a_flow_region_equals_the_full_flow_there() -> None:
    """A region of interest of the flow (``flow_origin``) gives the same prediction as the
    full image for points whose windows lie inside it, and zero motion for points outside."""
    z0 = 2.0
    prev, cur = _shifted_pair(8.0, -5.0, seed=3)
    flow = FlowEstimator().flow(prev, cur)
    inside = np.array([[0.0, 0.0, z0], [0.1, 0.05, z0]])  # project near the image centre
    outside = np.array([[-0.9, -0.6, z0]])  # projects near the top-left corner
    points = np.concatenate([inside, outside])
    d0, d1 = _depth(z0), _depth(z0)
    full, _ = propagate_points(points, flow, d0, d1, K)
    v0, v1, u0, u1 = 150, 330, 220, 420
    region, reliable = propagate_points(points, flow[v0:v1, u0:u1], d0, d1, K,
                                        flow_origin=(u0, v0))
    np.testing.assert_array_equal(region[:2], full[:2])
    assert reliable[:2].all() and not reliable[2]
    assert np.abs(full[2] - outside[0]).max() > 0.01  # it does move with the full flow ...
    np.testing.assert_allclose(region[2], outside[0])  # ... and not without flow there
    empty, _ = propagate_points(points, np.zeros((0, 0, 2), np.float32), d0, d1, K,
                                flow_origin=(0, 0))
    np.testing.assert_allclose(empty, points)
    with pytest.raises(InputError, match='does not fit'):
        propagate_points(points, flow[v0:v1, u0:u1], d0, d1, K, flow_origin=(u0, 400))


def test_propagate_points_reads_a_flow_field_at_working_resolution() -> None:
    """``FlowEstimator.flow(..., upsample=False)`` read with ``flow_scale`` predicts what the
    upsampled field predicts (within a few mm), for the whole image and for a region."""
    z0 = 2.0
    prev, cur = _shifted_pair(8.0, -5.0, seed=4)
    est = FlowEstimator()
    full = est.flow(prev, cur)
    small = est.flow(prev, cur, upsample=False)
    assert small.shape == (240, 320, 2)
    points = np.array([[0.0, 0.0, z0], [0.1, 0.05, z0], [-0.3, 0.2, z0]])
    d0 = _depth(z0)
    want, _ = propagate_points(points, full, d0, d0, K)
    got, reliable = propagate_points(points, small, d0, d0, K, flow_origin=(0, 0),
                                     flow_scale=(0.5, 0.5))
    assert reliable.all()
    np.testing.assert_allclose(got, want, atol=0.005)
    roi = est.flow(prev[100:400, 150:550], cur[100:400, 150:550], upsample=False)
    got, _ = propagate_points(points[:2], roi, d0, d0, K, flow_origin=(150, 100),
                              flow_scale=(roi.shape[1] / 400, roi.shape[0] / 300))
    np.testing.assert_allclose(got, want[:2], atol=0.005)
    for bad in ((0.0, 0.5), (0.5, 2.0), (0.5,), (-1.0, -1.0)):
        with pytest.raises(InputError, match='flow_scale'):
            propagate_points(points, small, d0, d0, K, flow_origin=(0, 0), flow_scale=bad)


def test_propagate_points_takes_the_motion_of_its_own_surface() -> None:
    """A finger (3 px wide bar at 1.5 m, moving 10 px right) over a torso (2.5 m, static): most
    of a 7x7 window around a point on the finger sees the torso, yet the point must take the
    finger's motion and depth (an unfiltered median would give zero motion and 2.5 m)."""
    yy, xx = np.mgrid[0:H, 0:W]
    finger = (np.abs(xx - 320) <= 1) & (np.abs(yy - 240) <= 40)
    flow = np.zeros((H, W, 2), np.float32)
    flow[finger, 0] = 10.0
    prev_depth = np.where(finger, 1.5, 2.5).astype(np.float32)
    finger_cur = (np.abs(xx - 330) <= 1) & (np.abs(yy - 240) <= 40)
    cur_depth = np.where(finger_cur, 1.52, 2.5).astype(np.float32)
    u, v = 320, 240
    p = _at(u, v, 1.5)
    out, reliable = propagate_points(p, flow, prev_depth, cur_depth, K, window=7)
    assert reliable[0]
    assert out[0, 2] == pytest.approx(1.52, abs=1e-6)  # not the torso's 2.5 m
    assert K.project(out)[0] == pytest.approx([u + 10, v], abs=1e-6)
    # A point on the torso 4 px beside the finger stays put.
    q = _at(316, v, 2.5)
    out, reliable = propagate_points(q, flow, prev_depth, cur_depth, K)
    assert reliable[0]
    np.testing.assert_allclose(out, q, atol=1e-6)


def test_occluded_point_keeps_its_depth() -> None:
    """A torso point (2.5 m) that a hand (disc at 1.5 m moving 10 px right) covers in the
    current frame keeps its own depth instead of jumping onto the hand, and is flagged."""
    flow, prev_depth, cur_depth = _moving_disc(30, (10, 0), (10.0, 0.0), (1.5, 1.52), 2.5)
    r = _at(356, 240, 2.5)
    out, reliable = propagate_points(r, flow, prev_depth, cur_depth, K)
    assert not reliable[0]
    np.testing.assert_allclose(out, r, atol=1e-6)


def test_propagate_points_follows_a_depth_change_of_its_neighbourhood() -> None:
    """The current depth is read near z + the neighbourhood's depth change, so a hand moving
    towards the camera by 15 cm (more than the 10 cm tolerance) keeps its surface."""
    flow = _constant_flow(4.0, 0.0)
    out, reliable = propagate_points(np.array([[0.1, 0.0, 2.0]]), flow, _depth(2.0),
                                     _depth(1.85), K)
    assert reliable[0]
    assert out[0, 2] == pytest.approx(1.85)


def test_point_that_slips_onto_a_surface_behind_is_lost() -> None:
    """A hand (disc at 2.85 m) moves 30 px down in front of the legs (3.0 m) but the flow says
    10 px: the moved window sees the legs, 15 cm deeper. The point must not be carried onto
    the legs: zero motion, its own depth, not reliable."""
    flow, prev_depth, cur_depth = _moving_disc(15, (0, 30), (0.0, 10.0), (2.85, 2.85), 3.0)
    p = _at(320, 228, 2.85)
    out, reliable = propagate_points(p, flow, prev_depth, cur_depth, K)
    assert not reliable[0]
    np.testing.assert_allclose(out, p, atol=1e-9)


def test_receding_surface_within_the_tolerance_is_followed() -> None:
    """A surface moving 8 cm away (less than the 10 cm tolerance) is followed, not lost."""
    out, reliable = propagate_points(np.array([[0.1, 0.0, 2.0]]), _constant_flow(4.0, 0.0),
                                     _depth(2.0), _depth(2.08), K)
    assert reliable[0]
    assert out[0, 2] == pytest.approx(2.08)
    assert K.project(out)[0, 0] == pytest.approx(K.project(np.array([[0.1, 0.0, 2.0]]))[0, 0] + 4)


def test_fallback_nan_depth_at_target() -> None:
    flow = _constant_flow(10.0, 0.0)
    cur_depth = _depth(2.0)
    cur_depth[:, 300:] = np.nan  # the whole target neighbourhood has no reading
    p = np.array([[(330 - K.cx) * 2.0 / K.fx, 0.0, 2.0]])
    out, reliable = propagate_points(p, flow, _depth(2.0), cur_depth, K)
    assert np.isfinite(out).all()
    assert not reliable[0]
    assert out[0, 2] == pytest.approx(2.0)  # previous depth (no neighbourhood change known)
    assert K.project(out)[0, 0] == pytest.approx(340.0)  # the flow is still applied


def test_fallback_nan_depth_only_near_target_uses_larger_window() -> None:
    flow = _constant_flow(10.0, 0.0)
    cur_depth = _depth(2.05)
    cur_depth[234:247, 334:347] = np.nan  # 13x13 hole around the target pixel (340, 240)
    p = _at(330, 240, 2.0)
    out, reliable = propagate_points(p, flow, _depth(2.0), cur_depth, K)
    assert not reliable[0]
    assert out[0, 2] == pytest.approx(2.05)


def test_fallback_nan_flow() -> None:
    flow = np.full((H, W, 2), np.nan, np.float32)
    p = np.array([[0.1, -0.1, 2.0]])
    out, reliable = propagate_points(p, flow, _depth(2.0), _depth(2.0), K)
    assert np.isfinite(out).all()
    assert not reliable[0]
    np.testing.assert_allclose(out, p, atol=1e-9)  # zero motion, same depth


def test_fallback_nan_flow_near_point_uses_larger_window() -> None:
    flow = _constant_flow(6.0, -2.0)
    flow[234:247, 314:327] = np.nan  # 13x13 hole around (320, 240)
    p = _at(320, 240, 2.0)
    out, reliable = propagate_points(p, flow, _depth(2.0), _depth(2.0), K)
    assert not reliable[0]
    assert K.project(out)[0] == pytest.approx([326.0, 238.0], abs=1e-6)


def test_points_outside_the_image_or_behind_the_camera_are_kept() -> None:
    flow = _constant_flow(5.0, 5.0)
    points = np.array([[5.0, 0.0, 1.0],     # far right of the image
                       [0.0, -3.0, 1.0],    # above
                       [0.0, 0.0, -1.0],    # behind the camera
                       [0.0, 0.0, 0.0],     # at the centre of projection
                       [0.0, 0.0, 2.0]])    # a normal point
    out, reliable = propagate_points(points, flow, _depth(2.0), _depth(2.0), K)
    assert np.isfinite(out).all()
    assert reliable.tolist() == [False, False, False, False, True]
    np.testing.assert_array_equal(out[:4], points[:4])
    assert not np.allclose(out[4], points[4])


def test_target_leaving_the_image_is_unreliable_but_finite() -> None:
    flow = _constant_flow(50.0, 0.0)
    p = np.array([[(620 - K.cx) * 2.0 / K.fx, 0.0, 2.0]])
    out, reliable = propagate_points(p, flow, _depth(2.0), _depth(2.0), K)
    assert np.isfinite(out).all() and not reliable[0]
    assert K.project(out)[0, 0] == pytest.approx(670.0)


def test_depth_far_from_the_point_is_not_used() -> None:
    """A point 0.5 m in front of every depth reading (e.g. a stale prediction) has no valid
    pixels: no motion is invented and it is not reliable."""
    flow = _constant_flow(7.0, 0.0)
    p = np.array([[0.0, 0.0, 1.5]])
    out, reliable = propagate_points(p, flow, _depth(2.0), _depth(2.0), K)
    assert not reliable[0]
    np.testing.assert_allclose(out, p)


def test_propagate_points_many_points_and_empty() -> None:
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(-0.8, 0.8, 20), rng.uniform(-0.6, 0.6, 20),
                              np.full(20, 2.0)])
    out, reliable = propagate_points(points, _constant_flow(3.0, 1.0), _depth(2.0),
                                     _depth(2.0), K)
    assert out.shape == (20, 3) and reliable.shape == (20,) and reliable.dtype == bool
    assert reliable.all()
    np.testing.assert_allclose(K.project(out), K.project(points) + [3.0, 1.0], atol=1e-9)
    out, reliable = propagate_points(np.zeros((0, 3)), _constant_flow(0, 0), _depth(2.0),
                                     _depth(2.0), K)
    assert out.shape == (0, 3) and reliable.shape == (0,)


def test_propagate_points_rejects_bad_inputs() -> None:
    p = np.array([[0.0, 0.0, 2.0]])
    flow, depth = _constant_flow(0, 0), _depth(2.0)
    with pytest.raises(InputError, match=r'flow has shape 480x639x2 .* 480x640x2'):
        propagate_points(p, flow[:, :-1], depth, depth, K)
    with pytest.raises(InputError, match='previous depth'):
        propagate_points(p, flow, depth[:-1], depth, K)
    with pytest.raises(InputError, match='current depth'):
        propagate_points(p, flow, depth, depth.T, K)
    with pytest.raises(InputError, match=r'\(N, 3\)'):
        propagate_points(np.zeros((2, 2)), flow, depth, depth, K)
    with pytest.raises(InputError, match='finite'):
        propagate_points(np.array([[0.0, np.nan, 2.0]]), flow, depth, depth, K)
    for window in (0, 4, -3, 2.5):
        with pytest.raises(InputError, match='window'):
            propagate_points(p, flow, depth, depth, K, window=window)
    with pytest.raises(InputError, match='depth_tolerance'):
        propagate_points(p, flow, depth, depth, K, depth_tolerance=0.0)
