"""One frame of a bag as the estimator saw it: why an end-effector was found or missed.

The tracker runs over the bag from its first frame (so its static background, floor and
tracks are those of ``endeff eval``) up to ``--frame``; that frame is drawn over its depth
image (near = bright):

- the foreground points, coloured by sub-band (Section 4.1; points no band reached: grey;
  sub-bands cut by the image border, the foreground box or a dropped table top, whose
  extremes are dropped as no ends (``drop_cut_ends``): white);
- each candidate's geodesic path to its entity's root (Section 4.2), a white line, and the
  candidate (the single-frame estimator's end-effector) as a red ring;
- the tracker's published end-effectors with their ids (:func:`draw_tracks`: filled when
  detected in this frame, a ring when predicted);
- the ground truth, green crosses.

Printed (JSON): per ground-truth point its distance to the nearest candidate and track, and
the sub-band, band and entity of the foreground point nearest to it, and whether that
sub-band is cut; per candidate its position, sub-band (graph node) and protrusion (its
geodesic distance to the root and the earlier paths, compared with g).

    python -m tools.frame_view BAG --frame N [--params YAML] [--out PNG]
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from endeff_ros.bag.reader import BagReader
from endeff_ros.cli_common import load_params_option, print_json
from endeff_ros.core.errors import InputError
from endeff_ros.core.graph import path_to_sources
from endeff_ros.core.nearest import nearest_point
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.single_frame import cut_nodes
from endeff_ros.core.tracker import Tracker, TrackerResult
from endeff_ros.core.types import Intrinsics, RGBDFrame
from endeff_ros.ros.convert import depth_to_rgb, draw_tracks

GROUND_TRUTH_BGR = (0, 255, 0)
CANDIDATE_BGR = (0, 0, 255)
PATH_BGR = (255, 255, 255)
UNBANDED_BGR = (90, 90, 90)
CUT_BGR = (255, 255, 255)


def run_to_frame(bag: Path, frame: int, params: EndeffParams | None = None,
                 ) -> tuple[RGBDFrame, npt.NDArray[np.float64], TrackerResult]:
    """The tracker over ``bag`` up to frame ``frame`` (0-based, in the bag's depth order):
    that frame, its ground truth (G, 3; empty when it has none) and the tracker's result.
    Frames the estimator refuses (:class:`InputError`) are skipped, as ``endeff eval`` does;
    ``frame`` itself must be usable. Raises ``IndexError`` when the bag is shorter."""
    tracker = Tracker(params or EndeffParams())
    count = 0
    with BagReader(bag) as reader:
        for i, (f, gt) in enumerate(reader.frames()):
            count = i + 1
            if i == frame:
                result = tracker.update(f)
                truth = np.zeros((0, 3)) if gt is None else np.asarray(gt)[:, :3]
                return f, truth, result
            try:
                tracker.update(f)
            except InputError:
                continue
    msg = f'{bag} has no frame {frame} (it has {count} frames)'
    raise IndexError(msg)


def _pixels(intrinsics: Intrinsics, points: npt.NDArray[np.float64]) -> npt.NDArray[np.int32]:
    return np.round(intrinsics.project(points)).astype(np.int32).reshape(-1, 2)


def _cut(frame: RGBDFrame, result: TrackerResult,
         params: EndeffParams | None) -> npt.NDArray[np.intp]:
    """The frame's cut sub-bands (:func:`cut_nodes`)."""
    est = result.estimate
    return cut_nodes(est.points, est.subband, frame.intrinsics, params or EndeffParams(),
                     est.cut)


def draw(frame: RGBDFrame, truth: npt.NDArray[np.float64], result: TrackerResult,
         params: EndeffParams | None = None) -> npt.NDArray[np.uint8]:
    """(H, W, 3) BGR picture of ``result``'s frame (see the module docstring)."""
    k = frame.intrinsics
    est = result.estimate
    img = depth_to_rgb(frame.depth)
    if len(est.points):
        n = int(est.subband.max()) + 1 if est.subband.size else 0
        colours = np.random.default_rng(0).integers(80, 256, (max(n, 1), 3))
        cut = np.isin(est.subband, _cut(frame, result, params))
        for (u, v), s, c in zip(_pixels(k, est.points), est.subband, cut):
            bgr = (UNBANDED_BGR if s < 0 else CUT_BGR if c
                   else tuple(int(x) for x in colours[s]))
            cv2.circle(img, (int(u), int(v)), 2, bgr, -1)
    graph = est.graph
    for entity in est.entities:
        for cand in entity.candidates:
            if graph is not None:
                path = path_to_sources(graph.pred[entity.root_node], cand.node)
                uv = _pixels(k, graph.centroids[path])
                cv2.polylines(img, [uv.reshape(-1, 1, 2)], False, PATH_BGR, 1, cv2.LINE_AA)
            u, v = _pixels(k, cand.position)[0]
            cv2.circle(img, (int(u), int(v)), 8, CANDIDATE_BGR, 2, cv2.LINE_AA)
    # draw_tracks takes and returns RGB; the picture is written with OpenCV (BGR).
    img = draw_tracks(img[:, :, ::-1], k, result.tracks)[:, :, ::-1].copy()
    for u, v in _pixels(k, truth[truth[:, 2] > 0]):
        cv2.drawMarker(img, (int(u), int(v)), GROUND_TRUTH_BGR, cv2.MARKER_CROSS, 14, 2)
    return img


def describe(frame: RGBDFrame, truth: npt.NDArray[np.float64], result: TrackerResult,
             params: EndeffParams | None = None) -> dict[str, Any]:
    """The JSON summary printed by :func:`main` (see the module docstring)."""
    est = result.estimate
    cut = _cut(frame, result, params) if len(est.points) else np.zeros(0, np.intp)
    cands = [c for e in est.entities for c in e.candidates]
    cand_pos = np.array([c.position for c in cands]).reshape(-1, 3)
    track_pos = np.array([t.position for t in result.tracks]).reshape(-1, 3)

    def nearest(points: npt.NDArray[np.float64]) -> list[float | None]:
        if not len(points):
            return [None] * len(truth)
        return nearest_point(points, truth)[0].tolist()

    rows = []
    for g, d_cand, d_track in zip(truth, nearest(cand_pos), nearest(track_pos)):
        rows.append({'position': np.round(g, 3).tolist(), 'nearest_candidate_m': d_cand,
                     'nearest_track_m': d_track})
    if len(est.points) and len(truth):
        d_fg, index = nearest_point(est.points, truth)
        for row, d, i in zip(rows, d_fg, index):
            row.update(nearest_foreground_m=float(d), subband=int(est.subband[i]),
                       band=int(est.band[i]), entity=int(est.entity[i]),
                       cut=bool(np.isin(est.subband[i], cut)))
    return {'ground_truth': rows,
            'candidates': [{'position': np.round(c.position, 3).tolist(), 'subband': c.node,
                            'protrusion_m': round(c.protrusion, 3)} for c in cands],
            'tracks': len(result.tracks), 'foreground_points': len(est.points)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m tools.frame_view', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag', type=Path)
    parser.add_argument('--frame', type=int, required=True, help='0-based depth frame index')
    parser.add_argument('--params', help='parameter file (YAML), as for endeff eval')
    parser.add_argument('--out', type=Path, default=Path('frame_view.png'))
    args = parser.parse_args(argv)
    params = load_params_option(args.params, 'frame_view')
    try:
        frame, truth, result = run_to_frame(args.bag, args.frame, params)
    except (IndexError, InputError) as exc:
        parser.exit(1, f'frame_view: {exc}\n')
    cv2.imwrite(str(args.out), draw(frame, truth, result, params))
    print_json({'bag': str(args.bag), 'frame': args.frame, 'out': str(args.out),
                **describe(frame, truth, result, params)})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
