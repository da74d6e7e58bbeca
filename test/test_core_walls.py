"""Large planes in the foreground (walls, a wall right behind a person) are dropped with the
floor (:func:`endeff_ros.core.surfaces.wall_points`); a body and small flat parts are not."""

from __future__ import annotations

import numpy as np
import pytest

from endeff_ros.core.cloud import foreground_cloud
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.types import KINECT_640 as K

# Only the rule under test: no floor, no background, every strided pixel a point.
PARAMS = EndeffParams(background=False, floor_removal=False, voxel_size=0.0)
FAR = 6.0  # beyond the default box's far face: no reading of the room behind


def empty(z: float = FAR) -> np.ndarray:
    return np.full((K.height, K.width), z, dtype=np.float32)


def paint(depth: np.ndarray, x0: float, x1: float, y0: float, y1: float, z: float) -> None:
    """A flat rectangle facing the camera (optical x right, y down), in front of what is there."""
    u0, u1 = (int(round(K.cx + K.fx * x / z)) for x in (x0, x1))
    v0, v1 = (int(round(K.cy + K.fy * y / z)) for y in (y0, y1))
    patch = depth[max(v0, 0):max(v1, 0), max(u0, 0):max(u1, 0)]
    np.minimum(patch, np.float32(z), out=patch)


def person(depth: np.ndarray, x: float = 0.0, z: float = 2.6) -> None:
    paint(depth, x - 0.09, x + 0.09, -0.85, -0.63, z)  # head
    paint(depth, x - 0.18, x + 0.18, -0.62, 0.0, z)  # torso
    for side in (-1, 1):
        paint(depth, x + side * 0.12 - 0.06, x + side * 0.12 + 0.06, 0.0, 0.85, z)  # legs
    paint(depth, x - 0.30, x - 0.20, -0.60, 0.0, z)  # arms
    paint(depth, x + 0.20, x + 0.30, -0.60, 0.0, z)


def noisy(depth: np.ndarray, seed: int = 0) -> np.ndarray:
    return depth + np.random.default_rng(seed).normal(0, 0.003, depth.shape).astype(np.float32)


def cloud(depth: np.ndarray, **kw: float) -> np.ndarray:
    return foreground_cloud(noisy(depth), K, PARAMS.replace(**kw)).points


def near(points: np.ndarray, z: float, tol: float = 0.05) -> int:
    return int(np.count_nonzero(np.abs(points[:, 2] - z) < tol))


def test_a_wall_right_behind_a_person_is_dropped_and_the_person_kept() -> None:
    depth = empty(3.0)  # a wall 0.4 m behind the person, filling the view
    person(depth)
    alone = empty()
    person(alone)
    with_wall, without = cloud(depth), cloud(alone)
    assert near(cloud(depth, wall_min_area=0.0), 3.0) > 10_000  # the wall, without the rule
    assert near(with_wall, 3.0) == 0
    assert near(with_wall, 2.6) == near(without, 2.6) > 500  # every point of the person


def test_an_oblique_wall_is_dropped() -> None:
    # A wall turned 27 degrees about the vertical axis: z = 3 + 0.5 x.
    u = np.arange(K.width, dtype=np.float64)
    z = 3.0 / (1.0 - 0.5 * (u - K.cx) / K.fx)
    depth = np.broadcast_to(z, (K.height, K.width)).astype(np.float32).copy()
    person(depth, x=-0.4, z=2.2)
    points = cloud(depth)
    assert near(points, 2.2) > 500
    assert np.count_nonzero(points[:, 2] > 2.4) == 0


@pytest.mark.parametrize(('width', 'dropped'), [(0.8, False), (1.5, True)])
def test_only_planes_of_at_least_wall_min_area_are_dropped(width: float, dropped: bool) -> None:
    depth = empty()
    paint(depth, -width / 2, width / 2, -0.5, 0.5, 2.5)  # a board of width x 1 m
    board = near(cloud(depth), 2.5)
    assert (board == 0) == dropped
    assert near(cloud(depth, wall_min_area=0.5), 2.5) == 0  # a lower threshold takes both


def test_plane_area_is_counted_per_connected_stretch() -> None:
    """A person's front and a cabinet beside them lie in one slab at 2.6 m; together they
    exceed 1 m^2, each alone does not: neither is dropped."""
    depth = empty()
    person(depth, x=-0.6)
    paint(depth, 0.2, 1.2, -0.35, 0.35, 2.6)  # cabinet front, 0.7 m^2, not touching the person
    points = cloud(depth)
    assert near(points, 2.6) == near(cloud(depth, wall_min_area=0.0), 2.6)


def test_a_slab_through_a_body_seen_edge_on_is_no_wall() -> None:
    """A body whose parts lie at different depths (a person bending towards the camera) has
    no frontal plane holding much of it, but a vertical slab through its middle, seen
    edge-on, holds a band of every part; each of those pixels views the slab at a grazing
    angle, and their footprints add up to more than a wall's 1 m^2. Projected onto the slab
    they cover a thin curve: not a wall, and every point of the body stays."""
    depth = empty()
    for i, z in enumerate([2.6, 3.0, 2.7, 2.9, 2.65, 2.95, 2.75, 2.85, 2.6, 3.0]):
        y0 = -1.0 + 0.2 * i
        paint(depth, -0.08, 0.08, y0 - 0.05, y0 + 0.25, z)  # overlapping: one stretch
    points = cloud(depth)
    assert len(points) == len(cloud(depth, wall_min_area=0.0)) > 1000
