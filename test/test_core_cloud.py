"""Section 3 of the core (depth -> foreground cloud) and the input checks of the core types.

Depth images are hand-made (a few pixels checked against the pinhole model) or ray-cast from the
synthetic scenes of :mod:`endeff_ros.synth.scenes` (the benchmark suites' bodies and renderer);
every random draw is seeded.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from endeff_ros.core.cloud import (
    FILL_AGREE_M,
    FILL_AGREE_PER_M,
    FILL_MIN_READINGS,
    MAX_RANGE_M,
    box_mask,
    depth_to_points,
    fill_dropouts,
    foreground_cloud,
    voxel_downsample,
)
from endeff_ros.core.errors import InputError, ParameterError
from endeff_ros.core.floor import FloorPlane, fit_floor
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.single_frame import estimate_points
from endeff_ros.core.types import KINECT_640, Intrinsics, RGBDFrame
from endeff_ros.ros.convert import depth_image_to_array
from endeff_ros.synth import scenes
from endeff_ros.synth.body import Entity
from endeff_ros.synth.render import Camera
from endeff_ros.synth.shapes import box, capsule

K_SMALL = Intrinsics(fx=50.0, fy=60.0, cx=3.5, cy=2.5, width=8, height=6)


def pinhole(u, v, z, k=K_SMALL):
    """The optical-frame point seen at pixel (u, v) with depth z."""
    return np.array([(u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z])


def as_set(points, decimals=9):
    """Rows of ``points`` as a set of rounded tuples (order-free comparison)."""
    return {tuple(np.round(p, decimals)) for p in np.asarray(points)}


def scene_points(shot):
    """A rendered ``scenes.Shot`` -> all valid points inside the default foreground box."""
    points = depth_to_points(shot.frame.depth, KINECT_640, stride=2)
    return points[box_mask(points, EndeffParams())]


def tilted(pitch_deg, roll_deg, height=1.1):
    """A camera ``height`` m up, pitched down by ``pitch_deg`` and rolled by ``roll_deg``."""
    return Camera(KINECT_640, height=height, pitch=math.radians(pitch_deg),
                  roll=math.radians(roll_deg), frame_id='camera')


def up(camera):
    """The floor's upward normal in the camera's optical frame."""
    return camera.rotation @ np.array([0.0, 1.0, 0.0])


def floor_args(params=None):
    params = params or EndeffParams()
    return {'distance': params.floor_distance, 'max_tilt_deg': params.floor_max_tilt_deg,
            'min_fraction': params.floor_min_fraction, 'iterations': params.floor_iterations}


# ---------------------------------------------------------------------------------------------
# depth_to_points
# ---------------------------------------------------------------------------------------------

def _depth_msg(pixels_mm):
    """A duck-typed ``sensor_msgs/Image`` in 16UC1 (millimetres)."""
    h, w = pixels_mm.shape
    return SimpleNamespace(encoding='16UC1', height=h, width=w, step=2 * w, is_bigendian=0,
                           data=pixels_mm.astype('<u2').tobytes())


def test_depth_to_points_32fc1_matches_pinhole():
    rng = np.random.default_rng(3)
    depth = rng.uniform(0.5, 4.0, (K_SMALL.height, K_SMALL.width)).astype(np.float32)
    points = depth_to_points(depth, K_SMALL)
    assert points.shape == (K_SMALL.width * K_SMALL.height, 3)
    assert points.dtype == np.float64
    expected = [pinhole(u, v, float(depth[v, u])) for v in range(K_SMALL.height)
                for u in range(K_SMALL.width)]
    assert as_set(points) == as_set(expected)
    # A few pixels by hand: the principal point lies on the optical axis.
    depth[2, 3] = 2.0  # (u, v) = (3, 2): half a pixel off cx and cy
    points = depth_to_points(depth, K_SMALL)
    row = points[np.argmin(np.linalg.norm(points - pinhole(3, 2, 2.0), axis=1))]
    np.testing.assert_allclose(row, [-0.5 * 2.0 / 50.0, -0.5 * 2.0 / 60.0, 2.0], atol=1e-12)


def test_depth_to_points_16uc1_converted_to_metres():
    mm = np.zeros((K_SMALL.height, K_SMALL.width), dtype=np.uint16)
    mm[0, 0] = 1234
    mm[5, 7] = 4000
    mm[2, 4] = 65535  # sensor garbage beyond MAX_RANGE_M
    depth = depth_image_to_array(_depth_msg(mm))
    assert depth.dtype == np.float32
    points = depth_to_points(depth, K_SMALL)
    assert len(points) == 2  # zeros are no reading, 65.5 m is beyond range
    expected = np.array([pinhole(0, 0, 1.234), pinhole(7, 5, 4.0)])
    got = points[np.argsort(points[:, 2])]
    np.testing.assert_allclose(got, expected, atol=1e-6)  # float32 millimetres


@pytest.mark.parametrize('bad', [0.0, np.nan, np.inf, -np.inf, -1.0, MAX_RANGE_M + 0.5, 65.535])
def test_depth_to_points_drops_invalid_pixels(bad):
    depth = np.full((K_SMALL.height, K_SMALL.width), 2.0, dtype=np.float32)
    depth[1, 1] = bad
    depth[4, 6] = bad
    points = depth_to_points(depth, K_SMALL)
    assert len(points) == depth.size - 2
    assert np.all(np.isfinite(points))
    assert np.all(points[:, 2] == 2.0)
    assert pinhole(1, 1, 2.0).round(9).tolist() not in points.round(9).tolist()


def test_depth_to_points_keeps_the_full_range():
    depth = np.full((K_SMALL.height, K_SMALL.width), np.nan, dtype=np.float32)
    depth[0, 0] = 19.5
    depth[0, 1] = 0.05
    points = depth_to_points(depth, K_SMALL)
    assert sorted(points[:, 2].round(5)) == [0.05, 19.5]


def test_depth_to_points_stride_and_z_range():
    depth = np.tile(np.linspace(0.5, 5.0, K_SMALL.width, dtype=np.float32),
                    (K_SMALL.height, 1))
    points = depth_to_points(depth, K_SMALL, stride=2)
    expected = [pinhole(u, v, float(depth[v, u])) for v in range(0, K_SMALL.height, 2)
                for u in range(0, K_SMALL.width, 2)]
    assert as_set(points, 6) == as_set(expected, 6)
    ranged = depth_to_points(depth, K_SMALL, z_range=(1.0, 3.0))
    assert len(ranged) > 0
    assert ranged[:, 2].min() >= 1.0
    assert ranged[:, 2].max() <= 3.0
    assert len(ranged) == np.count_nonzero((depth >= 1.0) & (depth <= 3.0))


# ---------------------------------------------------------------------------------------------
# box_mask
# ---------------------------------------------------------------------------------------------

def test_box_mask_keeps_the_inside_and_the_boundary():
    p = EndeffParams(box_min_x=-1.0, box_max_x=1.0, box_min_y=-0.5, box_max_y=1.5,
                     box_min_z=0.5, box_max_z=3.0)
    points = np.array([
        [0.0, 0.0, 1.0],     # inside
        [-1.0, 1.5, 3.0],    # on the boundary (closed box)
        [1.0, -0.5, 0.5],    # on the boundary
        [1.01, 0.0, 1.0],    # right of the box
        [-1.01, 0.0, 1.0],   # left
        [0.0, -0.51, 1.0],   # above
        [0.0, 1.51, 1.0],    # below
        [0.0, 0.0, 0.49],    # too close
        [0.0, 0.0, 3.01],    # too far
    ])
    assert box_mask(points, p).tolist() == [True, True, True] + [False] * 6


def test_box_mask_random_points_agree_with_the_definition():
    rng = np.random.default_rng(5)
    points = rng.uniform(-3, 5, (2000, 3))
    p = EndeffParams()
    inside = ((points[:, 0] >= p.box_min_x) & (points[:, 0] <= p.box_max_x)
              & (points[:, 1] >= p.box_min_y) & (points[:, 1] <= p.box_max_y)
              & (points[:, 2] >= p.box_min_z) & (points[:, 2] <= p.box_max_z))
    assert 0 < inside.sum() < len(points)
    np.testing.assert_array_equal(box_mask(points, p), inside)


# ---------------------------------------------------------------------------------------------
# fit_floor
# ---------------------------------------------------------------------------------------------

def _angle_deg(a, b):
    cos = np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b))
    return math.degrees(math.acos(min(1.0, abs(cos))))


@pytest.mark.parametrize('pitch, roll', [
    pytest.param(0.0, 0.0, id='level'),
    pytest.param(10.0, 0.0, id='pitched-down-10deg'),
    pytest.param(-6.0, 0.0, id='pitched-up-6deg'),
    pytest.param(0.0, 10.0, id='rolled-10deg'),
    pytest.param(8.0, -8.0, id='pitched-and-rolled-8deg'),
])
def test_fit_floor_finds_a_tilted_floor(pitch, roll):
    camera = tilted(pitch, roll)
    points = scene_points(scenes.shoot(scenes.person('arms_down', x=0.2), camera))
    floor = fit_floor(points, rng=np.random.default_rng(0), **floor_args())
    assert floor is not None
    # The floor's normal is the camera's view of the scene's up; the camera centre is
    # `height` above the floor.
    assert _angle_deg(floor.normal, up(camera)) < 1.0
    assert floor.normal @ up(camera) > 0  # oriented upwards
    assert np.linalg.norm(floor.normal) == pytest.approx(1.0)
    assert floor.offset == pytest.approx(camera.height, abs=0.01)
    # The floor's points are the ones it explains: the lowest visible points are on it.
    heights = floor.distance(points)
    assert np.count_nonzero(heights < -3 * EndeffParams().floor_distance) == 0


def test_foreground_cloud_removes_the_tilted_floor_and_reports_it():
    camera = tilted(10.0, 0.0)
    person = scenes.person('t_pose')
    head = person.prims[person.parts['head']]
    top = head.center[1] + head.size[1]  # the head ellipsoid is upright: 1.73 m
    # The box ends before the scene's back wall (5.5 m away), which the pitched camera sees
    # nearer than the default box's far face: only the floor rule is under test here.
    params = EndeffParams(box_max_z=4.3)
    points, floor, *_ = foreground_cloud(scenes.shoot(person, camera).frame.depth, KINECT_640,
                                         params)
    assert floor is not None
    assert _angle_deg(floor.normal, up(camera)) < 1.0
    assert np.all(floor.distance(points) > params.floor_distance - 1e-9)
    # What is left is the person: from just above the floor to the top of the head.
    heights = floor.distance(points)
    assert heights.max() == pytest.approx(top, abs=0.02)
    assert heights.min() < 0.08  # feet are kept (they stand on the floor)


def test_fit_floor_none_for_a_floating_star():
    points = scene_points(scenes.shoot(scenes.star(5), floor=False))
    assert len(points) > 1000
    assert fit_floor(points, rng=np.random.default_rng(0), **floor_args()) is None


def _table(top_y=0.75):
    """A table 2.0-2.8 m from the camera: a flat 1.2 x 0.8 m top, 3 cm thick, on four legs
    (the legs are below it). No end-effectors."""
    wood, eye = (0.5, 0.35, 0.2), np.eye(3)
    prims = [box([0.0, top_y - 0.015, -2.4], eye, [0.6, 0.015, 0.4], wood, 0, 'top')]
    prims += [capsule([x, 0.0, z], [x, top_y - 0.03, z], 0.035, [1, 0, 0], wood, 1, 'leg')
              for x in (-0.55, 0.55) for z in (-2.05, -2.75)]
    return Entity(prims, np.zeros((0, 3)), np.zeros(0, np.uint32), np.zeros(0, np.int64),
                  np.zeros(0))


def test_fit_floor_none_when_the_only_horizontal_surface_has_points_below():
    points = scene_points(scenes.shoot(_table(), floor=False))
    params = EndeffParams()
    # Premise: the table top alone would qualify as a floor by size and tilt (it holds more
    # than floor_min_fraction of the points, and it is level) ...
    top = FloorPlane(np.array([0.0, -1.0, 0.0]), 1.1 - 0.75)
    on_top = np.abs(top.distance(points)) < params.floor_distance
    assert on_top.mean() > params.floor_min_fraction
    # ... but the legs are below it, so it is not the floor.
    assert np.count_nonzero(top.distance(points) < -0.1) > 0.1 * len(points)
    assert fit_floor(points, rng=np.random.default_rng(0), **floor_args()) is None


def test_fit_floor_prefers_the_floor_under_a_table():
    points = scene_points(scenes.shoot(_table()))
    floor = fit_floor(points, rng=np.random.default_rng(0), **floor_args())
    assert floor is not None
    assert _angle_deg(floor.normal, [0.0, -1.0, 0.0]) < 1.0
    assert floor.offset == pytest.approx(1.1, abs=0.01)


def _seated_upper_body(stride=2):
    """Strided points of a Kinect 640 x 480 view (as Skeltrack's frames): a torso 1.2 m away
    facing the camera, its lap a level surface 0.45 m below the camera running towards it,
    cut by the image's lower border; nothing else (the recording removed the background)."""
    k = KINECT_640
    u, v = np.meshgrid(np.arange(0, k.width, stride), np.arange(0, k.height, stride))
    dx, dy = (u - k.cx) / k.fx, (v - k.cy) / k.fy
    z = np.full(u.shape, np.inf)
    torso = (np.abs(dx * 1.2) <= 0.25) & (dy * 1.2 > -0.4) & (dy * 1.2 < 0.45)
    z[torso] = 1.2
    with np.errstate(divide='ignore'):
        lap_z = np.where(dy > 0, 0.45 / dy, np.inf)
    lap = (lap_z >= 0.85) & (lap_z <= 1.2) & (np.abs(dx * lap_z) <= 0.2)
    z = np.where(lap & (lap_z < z), lap_z, z)
    ok = np.isfinite(z)
    points = np.stack([dx[ok] * z[ok], dy[ok] * z[ok], z[ok]], axis=1)
    return points, stride ** 2 / (k.fx * k.fy)


def test_fit_floor_no_floor_on_a_lap_the_image_border_cuts():
    """A level surface with nothing below it because the image ends there, holding enough
    points, is a floor by every other test; it shows a tenth of a square metre."""
    points, pixel_area = _seated_upper_body()
    lap = FloorPlane(np.array([0.0, -1.0, 0.0]), 0.45)
    share = np.mean(np.abs(lap.distance(points)) < EndeffParams().floor_distance)
    assert share > EndeffParams().floor_min_fraction  # premise
    assert fit_floor(points, **floor_args()) is not None  # no area given: a false floor
    assert fit_floor(points, **floor_args(), min_area=0.5, pixel_area=pixel_area) is None
    assert fit_floor(points, **floor_args(), min_area=0.05, pixel_area=pixel_area) is not None


def test_fit_floor_no_floor_through_the_camera():
    """Points along the fan of rays of one image row (a body cut by the lower border seen
    from above) lie on a plane through the camera's centre, level enough and with nothing
    below it: the camera cannot see a floor it stands on."""
    rng = np.random.default_rng(3)
    z = rng.uniform(1.0, 2.0, 4000)
    fan = np.stack([rng.uniform(-0.4, 0.4, 4000) * z, 0.35 * z, z], axis=1)
    body = np.stack([rng.uniform(-0.3, 0.3, 6000), rng.uniform(-0.5, 0.3, 6000),
                     np.full(6000, 1.5)], axis=1)
    points = np.concatenate([fan, body])
    assert np.all(body[:, 1] < 0.35 * body[:, 2])  # premise: nothing below the fan's plane
    assert fit_floor(points, rng=np.random.default_rng(0), **floor_args()) is None


def test_fit_floor_rejects_walls_and_tiny_inputs():
    rng = np.random.default_rng(7)
    wall = np.stack([rng.uniform(-1, 1, 3000), rng.uniform(-1, 1, 3000),
                     np.full(3000, 3.0)], axis=1)  # facing the camera
    assert fit_floor(wall, rng=np.random.default_rng(0), **floor_args()) is None
    assert fit_floor(wall[:2], **floor_args()) is None


# ---------------------------------------------------------------------------------------------
# voxel_downsample
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize('size', [0.01, 0.025, 0.07])
def test_voxel_downsample_reduces_and_keeps_the_means(size):
    rng = np.random.default_rng(11)
    points = rng.uniform([-0.4, -0.3, 1.5], [0.4, 0.5, 2.2], (4000, 3))
    out = voxel_downsample(points, size)
    cells = np.floor(points / size).astype(np.int64)
    keys, inverse, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    assert len(out) == len(keys) < len(points)
    means = np.stack([np.bincount(inverse, weights=points[:, a]) / counts for a in range(3)], 1)
    assert as_set(out, 9) == as_set(means, 9)
    # Every output point lies in its cell; the count-weighted mean is the input mean.
    out_cells = np.floor(out / size).astype(np.int64)
    assert {tuple(c) for c in out_cells} == {tuple(c) for c in keys}
    order = np.lexsort(np.flipud(out_cells.T))
    np.testing.assert_allclose((out[order] * counts[:, None]).sum(0) / counts.sum(),
                               points.mean(0), atol=1e-12)


def test_voxel_downsample_off_and_empty():
    points = np.random.default_rng(1).normal(size=(50, 3))
    assert voxel_downsample(points, 0.0) is points
    assert voxel_downsample(np.zeros((0, 3)), 0.05).shape == (0, 3)


def test_voxel_downsample_points_of_one_cell_collapse_to_their_mean():
    points = np.array([[0.01, 0.01, 1.01], [0.03, 0.02, 1.04], [0.02, 0.04, 1.03],
                       [0.26, 0.01, 1.01]])
    out = voxel_downsample(points, 0.05)
    assert as_set(out) == as_set([points[:3].mean(0), points[3]])


# ---------------------------------------------------------------------------------------------
# Bad inputs
# ---------------------------------------------------------------------------------------------

DEPTH = np.full((480, 640), 2.0, dtype=np.float32)


@pytest.mark.parametrize('make, message', [
    pytest.param(lambda: Intrinsics(0.0, 525.0, 319.5, 239.5, 640, 480),
                 r'intrinsics are unusable: fx=0\.0', id='fx-zero'),
    pytest.param(lambda: Intrinsics(525.0, -1.0, 319.5, 239.5, 640, 480),
                 r'intrinsics are unusable.*fy=-1\.0', id='fy-negative'),
    pytest.param(lambda: Intrinsics(math.nan, 525.0, 319.5, 239.5, 640, 480),
                 r'intrinsics are unusable: fx=nan', id='fx-nan'),
    pytest.param(lambda: Intrinsics(525.0, 525.0, math.inf, 239.5, 640, 480),
                 r'intrinsics are unusable.*cx=inf', id='cx-inf'),
    pytest.param(lambda: Intrinsics.from_k(np.zeros(9), 640, 480),
                 r'intrinsics are unusable.*calibrated', id='k-zeros'),
    pytest.param(lambda: Intrinsics.from_k(np.zeros(8), 640, 480),
                 r'K must have 9 elements, got 8', id='k-size'),
    pytest.param(lambda: Intrinsics(525.0, 525.0, 319.5, 239.5, 0, 480),
                 r'empty image size 0x480', id='empty-size'),
])
def test_bad_intrinsics(make, message):
    with pytest.raises(InputError, match=message):
        make()


@pytest.mark.parametrize('make, message', [
    pytest.param(lambda: RGBDFrame(0, 'cam', DEPTH[:240, :320], KINECT_640),
                 r'depth image is 320x240 but camera info says 640x480',
                 id='frame-depth-vs-intrinsics'),
    pytest.param(lambda: RGBDFrame(0, 'cam', DEPTH, KINECT_640,
                                   color=np.zeros((240, 320, 3), np.uint8)),
                 r'colour image is 320x240 but depth is 640x480', id='frame-colour-vs-depth'),
    pytest.param(lambda: RGBDFrame(0, 'cam', DEPTH[:, :, None], KINECT_640),
                 r'depth must be a 2-D image, got shape \(480, 640, 1\)', id='frame-3d-depth'),
    pytest.param(lambda: depth_to_points(DEPTH[:, :320], KINECT_640),
                 r'depth image is 320x480 but the intrinsics are for 640x480',
                 id='points-depth-vs-intrinsics'),
    pytest.param(lambda: depth_to_points(DEPTH[0], KINECT_640),
                 r'depth must be 2-D, got shape \(640,\)', id='points-1d-depth'),
    pytest.param(lambda: depth_to_points(np.full((480, 640), 2000, np.uint16), KINECT_640),
                 r'depth must be float metres, got dtype uint16', id='points-uint16-depth'),
    pytest.param(lambda: depth_to_points(np.full((480, 640), 2, np.int32), KINECT_640),
                 r'depth must be float metres, got dtype int32', id='points-int32-depth'),
])
def test_bad_frames(make, message):
    with pytest.raises(InputError, match=message):
        make()


def test_good_frame_with_colour_is_accepted():
    frame = RGBDFrame(0, 'cam', DEPTH, KINECT_640, color=np.zeros((480, 640, 3), np.uint8))
    assert frame.depth.shape == (480, 640)


@pytest.mark.parametrize('changes, message', [
    ({'band_delta': 0.0}, r'band_delta=0\.0 is outside \[0\.005, 1\.0\]'),
    ({'band_eta': 0}, r'band_eta=0 is outside'),
    ({'attach_points': 0}, r'attach_points=0 is outside'),
    ({'voxel_size': 0.5}, r'voxel_size=0\.5 is outside'),
    ({'pixel_stride': 9}, r'pixel_stride=9 is outside'),
    ({'memory_sigma': 1.5}, r'memory_sigma=1\.5 is outside'),
    ({'min_geodesic': -0.1}, r'min_geodesic=-0\.1 is outside'),
    ({'box_min_x': 1.0, 'box_max_x': 0.5}, r'box_min_x must be smaller than box_max_x'),
    ({'box_min_z': 3.0, 'box_max_z': 3.0}, r'box_min_z must be smaller than box_max_z'),
    ({'flow_method': 'ldof'}, r"flow_method must be 'dis' or 'farneback'"),
])
def test_out_of_range_parameters(changes, message):
    with pytest.raises(ParameterError, match=message):
        EndeffParams(**changes)
    with pytest.raises(ParameterError, match=message):
        EndeffParams().replace(**changes)


def test_parameter_dict_errors():
    with pytest.raises(ParameterError, match=r'unknown parameter\(s\): no_such_thing'):
        EndeffParams.from_dict({'no_such_thing': 1})
    with pytest.raises(ParameterError, match=r'parameter band_eta must be int'):
        EndeffParams.from_dict({'band_eta': 2.5})
    assert EndeffParams.from_dict({'band_delta': 1}).band_delta == 1.0


def test_depth_median_removes_a_flying_pixel_and_fills_a_pinhole():
    """The optional 3x3 median: a lone pixel 1 m behind a plane disappears, a one-pixel hole
    in the plane is filled, and without the option both are kept as they are."""
    k = Intrinsics(525.0, 525.0, 31.5, 23.5, 64, 48)
    depth = np.full((48, 64), 2.0, dtype=np.float32)
    depth[20, 30] = 3.0  # flying pixel
    depth[10, 10] = np.nan  # pinhole
    raw = depth_to_points(depth, k)
    filtered = depth_to_points(depth, k, median=True)
    assert np.count_nonzero(raw[:, 2] > 2.5) == 1 and len(raw) == 48 * 64 - 1
    assert np.count_nonzero(filtered[:, 2] > 2.5) == 0
    assert len(filtered) == 48 * 64
    np.testing.assert_allclose(filtered[:, 2], 2.0)


def test_fit_floor_finds_a_floor_that_a_wall_outnumbers():
    """A level camera and a wall filling the box: the floor is about a tenth of the points, so
    no triple of the hypothesis table lies on it; a local plane around one of its points
    does (the defaults, and the wall rule off so that it cannot drop the floor instead)."""
    from test_background import CHAIR_Z, add_chair, add_person, room

    from endeff_ros.core.cloud import foreground_cloud

    depth = room().copy()
    add_chair(depth)
    add_person(depth, 0.2, 0.5, z=CHAIR_Z + 0.1)
    params = EndeffParams(wall_min_area=0.0)
    floor = foreground_cloud(depth, KINECT_640, params).floor
    assert floor is not None
    assert _angle_deg(floor.normal, [0.0, -1.0, 0.0]) < 2.0


def test_a_known_floor_follows_the_floor_it_sees():
    """The tracker passes each frame the floor of the frame before. A first fit that is off
    (2 degrees of roll and 3 cm of height: a RANSAC sample biased by furniture) is pulled
    towards the floor the frames show, through the points near it, instead of being kept for
    the rest of the stream."""
    camera = tilted(10.0, 0.0)
    depth = scenes.shoot(scenes.person('arms_down', x=0.2), camera).frame.depth
    params = EndeffParams(box_max_z=4.3)
    truth = up(camera)
    c, s = math.cos(math.radians(2.0)), math.sin(math.radians(2.0))  # rolled about the view
    normal = np.array([c * truth[0] - s * truth[1], s * truth[0] + c * truth[1], truth[2]])
    floor = FloorPlane(normal, camera.height + 0.03)
    errors = []
    for _ in range(20):
        floor = foreground_cloud(depth, KINECT_640, params, floor=floor).floor
        errors.append((_angle_deg(floor.normal, truth), abs(floor.offset - camera.height)))
    assert errors[0][0] < 2.0 and errors[0][1] < 0.03  # each frame moves it closer
    assert errors[-1][0] < 0.2 and errors[-1][1] < 0.005


def test_a_floor_to_refit_is_fitted_anew_or_kept_when_none_is_found():
    """After a camera motion the tracker asks for the floor to be fitted anew
    (``refit``): where the frame shows one, the fit replaces the old plane; where it shows
    none (a view of the wall, or a failed fit), the old plane is kept rather than no floor
    at all, which would leave the whole floor foreground, and is still to be fitted anew in
    the next frame."""
    camera = tilted(10.0, 0.0)
    stale = FloorPlane(up(tilted(0.0, 0.0)), camera.height, refit=True)
    params = EndeffParams(box_max_z=4.3)
    person = scenes.person('arms_down', x=0.2)
    floor = foreground_cloud(scenes.shoot(person, camera).frame.depth, KINECT_640, params,
                             floor=stale).floor
    assert _angle_deg(floor.normal, up(camera)) < 1.0 and not floor.refit
    kept = foreground_cloud(scenes.shoot(person, camera, floor=False).frame.depth, KINECT_640,
                            params, floor=stale).floor
    assert np.array_equal(kept.normal, stale.normal) and kept.offset == stale.offset
    assert kept.refit


def test_foreground_points_carry_their_pixels_mean_colour():
    """With ``color_edge_rgb`` > 0 and a colour image, each foreground point (voxel) carries
    the mean colour of its pixels: a board at 2 m, red on the left, blue on the right, gives
    red and blue points and mixes only in the voxels across the line; the points are those
    of the run without colours. Off, or without a colour image, there are none."""
    depth = np.full((480, 640), np.nan, np.float32)
    depth[140:340, 220:420] = 2.0
    color = np.zeros((480, 640, 3), np.uint8)
    color[:, :320] = (255, 0, 0)
    color[:, 320:] = (0, 0, 255)
    params = EndeffParams(floor_removal=False, wall_min_area=0.0, color_edge_rgb=35.0)
    with_colors = foreground_cloud(depth, KINECT_640, params, color=color)
    plain = foreground_cloud(depth, KINECT_640, params)
    assert plain.colors is None
    np.testing.assert_array_equal(with_colors.points, plain.points)
    cols = with_colors.colors
    assert cols is not None and cols.shape == (len(plain.points), 3)
    red = with_colors.points[:, 0] < -0.03
    blue = with_colors.points[:, 0] > 0.03
    assert red.any() and blue.any()
    np.testing.assert_allclose(cols[red], [[255.0, 0.0, 0.0]] * int(red.sum()))
    np.testing.assert_allclose(cols[blue], [[0.0, 0.0, 255.0]] * int(blue.sum()))
    np.testing.assert_allclose(cols.sum(axis=1), 255.0)  # the line's voxels mix the two
    off = params.replace(color_edge_rgb=0.0)
    assert foreground_cloud(depth, KINECT_640, off, color=color).colors is None


# ---------------------------------------------------------------------------------------------
# fill_dropouts
# ---------------------------------------------------------------------------------------------

def _fill_reference(depth, stride):
    """fill_dropouts written out pixel by pixel (float64): the definition it must match."""
    d = np.asarray(depth, dtype=np.float64)
    ok = np.isfinite(d) & (d > 0) & (d <= MAX_RANGE_M)
    z = d[::stride, ::stride].copy()

    def block(v, u):  # readings in the block that strided pixel (v, u) starts
        if not (0 <= v < z.shape[0] and 0 <= u < z.shape[1]):
            return 0
        return int(ok[v * stride:(v + 1) * stride, u * stride:(u + 1) * stride].sum())

    for v in range(z.shape[0]):
        for u in range(z.shape[1]):
            if z[v, u] > 0:
                continue
            rows = slice(max(0, (v - 1) * stride), (v + 2) * stride)
            cols = slice(max(0, (u - 1) * stride), (u + 2) * stride)
            readings = d[rows, cols][ok[rows, cols]]
            if len(readings) < FILL_MIN_READINGS:
                continue
            inside = any(block(v + a, u + b) and block(v - a, u - b)
                         for a, b in ((0, 1), (1, 0), (1, 1), (1, -1)))
            scattered = max(block(v + a, u + b) for a in (-1, 0, 1)
                            for b in (-1, 0, 1)) <= stride * stride / 2
            if not (inside or scattered):
                continue
            tol = 0.5 * (FILL_AGREE_M + FILL_AGREE_PER_M * readings.mean())
            if readings.std() <= tol:
                z[v, u] = readings.mean()
    return z


@pytest.mark.parametrize(('stride', 'shape'), [(2, (24, 32)), (2, (23, 31)), (3, (20, 25)),
                                               (1, (12, 16))])
def test_fill_dropouts_matches_its_definition(stride, shape):
    """Random sparse surfaces at a few depths, with every kind of no-reading (NaN, 0, inf,
    negative, beyond the range), odd image sizes included: filled exactly as the pixel-by-pixel
    definition fills (the mean of the 3 x 3 blocks' readings when at least two agree, inside
    the surface or where its readings are scattered)."""
    rng = np.random.default_rng(stride * 100 + shape[1])
    depth = rng.choice([1.5, 2.5, 4.0], size=shape).astype(np.float32)
    depth = np.repeat(np.repeat(depth[::8, ::8], 8, axis=0), 8, axis=1)[:shape[0], :shape[1]]
    depth = depth + rng.normal(0, 0.004, shape).astype(np.float32)
    drop = rng.random(shape)
    depth[drop < 0.55] = np.nan
    depth[(drop >= 0.55) & (drop < 0.6)] = 0
    depth[(drop >= 0.6) & (drop < 0.62)] = np.inf
    depth[(drop >= 0.62) & (drop < 0.63)] = -1
    depth[(drop >= 0.63) & (drop < 0.64)] = MAX_RANGE_M + 5
    got = fill_dropouts(depth, stride)
    want = _fill_reference(depth, stride)
    assert got.shape == depth[::stride, ::stride].shape and got.dtype == np.float32
    filled = ~(depth[::stride, ::stride] > 0) & (got > 0)
    assert np.array_equal(filled, ~(depth[::stride, ::stride] > 0) & (want > 0))
    assert filled.any()
    np.testing.assert_allclose(got[filled], want[filled], atol=2e-5)
    kept = depth[::stride, ::stride] > 0  # readings are never changed (inf and beyond too)
    assert np.array_equal(got[kept], depth[::stride, ::stride][kept])


def test_fill_dropouts_rebuilds_a_sparse_surface_but_not_across_a_depth_edge():
    """A ToF-like surface read in one pixel of ten: the strided image keeps a tenth of its
    pixels, the filled one most of them, each at the surface's depth; beside it a surface
    0.5 m farther: no pixel takes a depth between the two."""
    rng = np.random.default_rng(3)
    depth = np.full((120, 160), 4.0, dtype=np.float32)
    depth[:, 80:] = 4.5
    depth += rng.normal(0, 0.005, depth.shape).astype(np.float32)
    depth[rng.random(depth.shape) < 0.9] = np.nan
    raw = depth[::2, ::2]
    got = fill_dropouts(depth, 2)
    assert np.count_nonzero(raw > 0) < 0.15 * raw.size
    assert np.count_nonzero(got > 0) > 0.6 * got.size
    near, far = got[:, :39], got[:, 41:]
    assert np.all(np.abs(near[near > 0] - 4.0) < 0.02)
    assert np.all(np.abs(far[far > 0] - 4.5) < 0.02)
    between = (got > 4.05) & (got < 4.45)
    assert not between.any()


def test_fill_dropouts_needs_two_readings():
    """One reading in a window is no surface: nothing around it is filled; two scattered
    readings that agree are."""
    depth = np.full((12, 12), np.nan, dtype=np.float32)
    depth[5, 5] = 2.0
    got = fill_dropouts(depth, 2)
    assert np.count_nonzero(got > 0) == 0
    depth[6, 7] = 2.01
    got = fill_dropouts(depth, 2)
    assert np.count_nonzero(got > 0) > 0
    np.testing.assert_allclose(got[got > 0], 2.005, atol=1e-5)


def test_fill_dropouts_does_not_grow_a_solid_outline():
    """A part read in full against no reading at all (a background the sensor or the
    recording left out): its outline's neighbours are not filled, holes inside it are."""
    depth = np.full((40, 40), np.nan, dtype=np.float32)
    depth[10:30, 10:30] = 2.0
    depth[20, 20] = np.nan  # a hole, at a strided pixel
    got = fill_dropouts(depth, 2)
    assert got[10, 10] == np.float32(2.0)  # the hole
    outline = (got > 0) & ~(depth[::2, ::2] > 0)
    assert np.count_nonzero(outline) == 1


def test_a_sparse_part_keeps_its_entity_with_dropouts_filled():
    """A block 0.3 x 0.8 m at 4 m that the sensor reads in one pixel of ten: from the raw
    strided image its points are too sparse for the density test (Eq. 3) and no entity is
    left; with ``dropout_fill`` (the default) it is one entity again."""
    k = Intrinsics(365.5, 365.5, 255.5, 211.5, 512, 424)
    rng = np.random.default_rng(5)
    depth = np.full((424, 512), np.nan, dtype=np.float32)
    u0, u1 = int(255.5 - 0.15 * 365.5 / 4), int(255.5 + 0.15 * 365.5 / 4)
    v0, v1 = int(211.5 - 0.4 * 365.5 / 4), int(211.5 + 0.4 * 365.5 / 4)
    depth[v0:v1, u0:u1] = 4.0 + rng.normal(0, 0.005, (v1 - v0, u1 - u0))
    depth[rng.random(depth.shape) < 0.9] = np.nan
    params = EndeffParams(floor_removal=False, background=False, wall_min_area=0.0,
                          table_min_area=0.0)
    entities = {}
    for fill in (False, True):
        p = params.replace(dropout_fill=fill)
        cloud = foreground_cloud(depth, k, p)
        entities[fill] = len(estimate_points(cloud.points, p).entities)
    assert entities == {False: 0, True: 1}
