"""Dead margins of registered depth (core/readable.py): found where the readings stop along a
straight line, not where the scene stops them; a body cut by a margin has no end there."""

from __future__ import annotations

import numpy as np
from test_background import PARAMS, add_person, room

from endeff_ros.core.readable import ReadableArea, fit_edges, strided_read
from endeff_ros.core.single_frame import estimate_frame
from endeff_ros.core.tracker import Tracker
from endeff_ros.core.types import KINECT_640 as K
from endeff_ros.core.types import RGBDFrame

STRIDE = 2


def kinect_margins(depth: np.ndarray) -> np.ndarray:
    """No reading in rows 0-33 and 464-479, columns 0-40 and 605-639 (Kinect v1 registered)."""
    out = depth.copy()
    out[:34], out[464:], out[:, :41], out[:, 605:] = np.nan, np.nan, np.nan, np.nan
    return out


def hexagon(depth: np.ndarray, corner: float = 0.2) -> np.ndarray:
    h, w = depth.shape
    u = np.arange(w) + 0.5
    v = (np.arange(h) + 0.5)[:, None]
    cut = corner * w * np.abs(v - 0.5 * h) / (0.5 * h)
    out = depth.copy()
    out[(u < cut) | (w - u < cut)] = np.nan
    return out


def test_kinect_bands_are_found_at_their_rows_and_columns():
    edges = fit_edges(strided_read(kinect_margins(room()), STRIDE), STRIDE, 3)
    assert all(f is not None for f in (edges.left, edges.right, edges.top, edges.bottom))
    assert np.allclose(edges.left.line * STRIDE, 41, atol=2)
    assert np.allclose(edges.right.line * STRIDE, 35, atol=2)
    assert np.allclose(edges.top.line * STRIDE, 34, atol=2)
    assert np.allclose(edges.bottom.line * STRIDE, 16, atol=2)
    u = np.array([43.0, 320.0, 320.0, 603.0])
    v = np.array([240.0, 36.0, 240.0, 240.0])
    assert edges.near(u, v, 3).tolist() == [True, True, False, True]


def test_no_margin_no_edges():
    edges = fit_edges(strided_read(room(), STRIDE), STRIDE, 3)
    assert edges.left is edges.right is edges.top is edges.bottom is None


def test_the_hexagons_corners_are_found():
    edges = fit_edges(strided_read(hexagon(room()), STRIDE), STRIDE, 3)
    assert edges.left is not None and edges.right is not None
    assert edges.near(np.array([0.2 * 640 * 0.5 + 2]), np.array([120.0]), 3)[0]  # on the cut
    assert not edges.near(np.array([40.0]), np.array([240.0]), 3)[0]  # the side's middle


def test_a_band_beyond_range_over_a_head_is_no_margin():
    """A time-of-flight sensor reads nothing beyond its range: above a far wall's curved
    boundary, and above a person's head that rises into that band. The edge follows the
    scene: no top line, the head is no cut end."""
    depth = room()
    add_person(depth, 0.0, 0.6, z=2.0)
    v = np.arange(K.height)[:, None]
    u = np.arange(K.width)[None, :]
    beyond = (depth > 3.0) & (v < 150 + 60 * np.cos((u - 320) / 320 * np.pi / 2) - 60)
    depth = np.where(beyond, np.nan, depth).astype(np.float32)
    edges = fit_edges(strided_read(depth, STRIDE), STRIDE, 3)
    head_top = np.array([320.0]), np.array([K.cy + K.fy * (1.1 - 1.70) / 2.0 + 2])
    assert edges.top is None or not edges.near(*head_top, 3)[0]


def test_learnt_from_the_stream_a_person_does_not_hide_the_edge():
    """A person standing in the left margin's edge for a frame: the readings of earlier frames
    keep the line where the sensor's readings stop."""
    area = ReadableArea()
    for _ in range(3):
        area.update(kinect_margins(room()), STRIDE, 3)
    occluded = kinect_margins(room())
    occluded[100:400, 41:120] = np.nan  # a black coat absorbs the light
    edges = area.update(occluded, STRIDE, 3)
    assert np.allclose(edges.left.line * STRIDE, 41, atol=2)


def _cut_person(cut: bool, bottom_rows: int = 16) -> list[float]:
    """Heights above the image's bottom margin (px) of the ends found on a person whose legs
    the Kinect's bottom margin (``bottom_rows`` deep) cuts (1.6 m from the camera), tracked
    and single-frame."""
    depth = room()
    add_person(depth, 0.0, 0.6, z=1.6)
    depth = kinect_margins(depth)
    depth[480 - bottom_rows:] = np.nan
    params = PARAMS.replace(cut_dead_margins=cut, background=False)
    tracker = Tracker(params)
    for k in range(3):
        result = tracker.update(RGBDFrame(stamp_ns=k * 33_333_333, frame_id='camera',
                                          depth=depth, intrinsics=K))
    est = estimate_frame(RGBDFrame(stamp_ns=0, frame_id='camera', depth=depth,
                                   intrinsics=K), params)
    edge = 480 - bottom_rows
    tracked = [edge - (K.fy * t.position[1] / t.position[2] + K.cy) for t in result.tracks]
    single = [edge - (K.fy * p[1] / p[2] + K.cy) for p in est.positions()]
    return tracked + single


def test_a_body_cut_by_a_deep_margin_has_no_end_there():
    assert min(_cut_person(False, 48)) < 60  # the cut legs' ends, above the margin's edge
    assert min(_cut_person(True, 48)) > 60


def test_a_thin_margin_cuts_no_end():
    """The Kinect's bottom band (16 rows, 3 % of the image) hides a few centimetres of what
    ends in it: the end at its edge is kept, as without the rule."""
    assert min(_cut_person(True)) < 60
    assert sorted(_cut_person(True)) == sorted(_cut_person(False))


def test_the_edges_are_fitted_again_only_when_a_sides_profile_moves(monkeypatch):
    """A pixel beyond range read for the first time inside the area (a person walking in
    front of it) leaves every edge profile, and so the fit, as it was; one read inside the
    margin moves a profile and the edges are fitted again."""
    import endeff_ros.core.readable as readable

    fits = []
    fit = readable.fit_edges
    monkeypatch.setattr(readable, 'fit_edges', lambda *a, **k: fits.append(1) or fit(*a, **k))
    scene = kinect_margins(room())
    scene[200:260, 300:340] = np.nan  # a hole beyond range in the middle of the image
    area = ReadableArea()
    first = area.update(scene, STRIDE, 3)
    inside = scene.copy()
    inside[200:260, 300:340] = 2.0  # a person in front of it
    assert area.update(inside, STRIDE, 3) is first and len(fits) == 1
    margin = inside.copy()
    margin[100:140, 10:41] = 2.0  # readings inside the left band
    moved = area.update(margin, STRIDE, 3)
    assert moved is not first and len(fits) == 2
