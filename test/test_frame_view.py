"""tools.frame_view: one frame's foreground, paths, candidates, tracks and ground truth."""

from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest

from tools import frame_view

FRAME = 20


@pytest.fixture(scope='module')
def viewed(room_bag):
    bag, _ = room_bag
    return frame_view.run_to_frame(bag, FRAME)


def test_runs_the_tracker_up_to_the_frame(room_bag, viewed):
    bag, _ = room_bag
    frame, truth, result = viewed
    with frame_view.BagReader(bag) as reader:
        stamps = [f.stamp_ns for f, _ in reader.frames()]
    assert frame.stamp_ns == result.stamp_ns == stamps[FRAME]
    assert truth.shape[1] == 3 and len(truth) > 0
    assert result.tracks, 'the tracker has published end-effectors by then'
    # The same tracks as a tracker fed every frame up to it (ids depend on the history).
    tracker = frame_view.Tracker()
    with frame_view.BagReader(bag) as reader:
        for i, (f, _) in enumerate(reader.frames()):
            expected = tracker.update(f)
            if i == FRAME:
                break
    assert [t.id for t in result.tracks] == [t.id for t in expected.tracks]
    assert np.allclose([t.position for t in result.tracks],
                       [t.position for t in expected.tracks])


def test_draws_ground_truth_candidates_and_sub_bands(viewed):
    frame, truth, result = viewed
    img = frame_view.draw(frame, truth, result)
    assert img.shape == (*frame.depth.shape, 3) and img.dtype == np.uint8
    h, w = frame.depth.shape
    inside = 0
    for u, v in np.round(frame.intrinsics.project(truth)).astype(int):
        if 6 <= u < w - 6 and 6 <= v < h - 6:
            inside += 1
            # A cross centred on the point: its centre and both arms.
            for du, dv in ((0, 0), (-6, 0), (6, 0), (0, -6), (0, 6)):
                assert tuple(img[v + dv, u + du]) == frame_view.GROUND_TRUTH_BGR
    assert inside > 0
    red = np.all(img == frame_view.CANDIDATE_BGR, axis=2)
    n_cands = sum(len(e.candidates) for e in result.estimate.entities)
    assert n_cands > 0 and red.any()
    # Sub-band colours: more distinct point colours than the fixed marks and the grey depth.
    colours = {tuple(c) for c in img.reshape(-1, 3)[::7] if len(set(c)) > 1}
    assert len(colours) > 10


def test_describe_measures_each_ground_truth_point(viewed):
    frame, truth, result = viewed
    d = frame_view.describe(frame, truth, result)
    assert len(d['ground_truth']) == len(truth)
    tracks = np.array([t.position for t in result.tracks])
    for row, g in zip(d['ground_truth'], truth):
        assert row['nearest_track_m'] == pytest.approx(
            np.linalg.norm(tracks - g, axis=1).min())
        assert row['subband'] >= -1 and row['nearest_foreground_m'] >= 0
    n_cands = sum(len(e.candidates) for e in result.estimate.entities)
    assert len(d['candidates']) == n_cands


def test_main_writes_the_picture_and_refuses_a_missing_frame(room_bag, tmp_path, capsys):
    bag, _ = room_bag
    out = tmp_path / 'view.png'
    assert frame_view.main([str(bag), '--frame', '3', '--out', str(out)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report['frame'] == 3 and report['out'] == str(out)
    assert cv2.imread(str(out)) is not None
    with pytest.raises(SystemExit) as exc:
        frame_view.main([str(bag), '--frame', '100000', '--out', str(tmp_path / 'x.png')])
    assert exc.value.code == 1
    with frame_view.BagReader(bag) as reader:
        n = sum(1 for _ in reader.frames())
    assert f'has no frame 100000 (it has {n} frames)' in capsys.readouterr().err


def test_cut_sub_bands_are_marked(viewed):
    """Sub-bands the image border cuts are drawn white and flagged in the summary. The
    intrinsics are narrowed to the left half of the image, so that the body is cut."""
    frame, truth, result = viewed
    est = result.estimate
    u = frame.intrinsics.project(est.points)[:, 0]
    half = int(np.median(u))
    narrow = dataclasses.replace(
        frame, depth=frame.depth[:, :half].copy(),
        color=None if frame.color is None else frame.color[:, :half].copy(),
        intrinsics=dataclasses.replace(frame.intrinsics, width=half))
    cut = frame_view.cut_nodes(est.points, est.subband, narrow.intrinsics,
                               frame_view.EndeffParams())
    assert cut.size > 0
    img = frame_view.draw(narrow, truth[:0], result)
    on_cut = np.isin(est.subband, cut)
    uv = np.round(narrow.intrinsics.project(est.points)).astype(int)
    white = [tuple(img[v, u]) == frame_view.CUT_BGR for u, v in uv[on_cut]
             if 0 <= u < half and 0 <= v < frame.depth.shape[0]]
    assert white and np.mean(white) > 0.5
    d = frame_view.describe(narrow, truth, result)
    rows = [row for row in d['ground_truth'] if 'subband' in row]
    assert rows
    for row in rows:
        assert row['cut'] == bool(np.isin(row['subband'], cut))
