"""The README's picture: the tracker's end-effectors on a synthetic frame, with ground truth.

``python -m tools.figure [--sequence two_people] [--frame 40] [--out PNG]`` (default
``docs/images/result_frame.png``) runs the tracker over a paper-suite sequence up to
``--frame`` and draws, side by side, the colour image with the tracked end-effectors (filled:
detected, ring: predicted; the id beside it, the geodesic path to the root as a line) and the
depth image with the ground truth (white crosses).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from endeff_ros.core.tracker import Tracker
from endeff_ros.core.types import RGBDFrame
from endeff_ros.ros.convert import depth_to_rgb, draw_tracks
from endeff_ros.synth import render_sequence


def figure(sequence: str, frame: int) -> np.ndarray:
    """(H, 2W, 3) RGB picture of frame ``frame`` of ``sequence``."""
    tracker = Tracker()
    shown = None
    for f in render_sequence(sequence):
        if f.depth is None:
            continue
        result = tracker.update(RGBDFrame(f.stamp_ns, f.frame_id, f.depth, f.intrinsics,
                                          f.color))
        if f.index >= frame and f.color is not None:
            shown = (f, result)
            break
    if shown is None:
        msg = f'{sequence} has no frame {frame} with colour'
        raise SystemExit(msg)
    f, result = shown
    left = draw_tracks(f.color, f.intrinsics, result.tracks)
    right = depth_to_rgb(f.depth)
    for u, v in np.round(f.intrinsics.project(f.gt)).astype(int):
        cv2.drawMarker(right, (int(u), int(v)), (255, 255, 255), cv2.MARKER_CROSS, 14, 2)
    for img, text in ((left, 'end-effectors (tracker)'), (right, 'depth, ground truth')):
        cv2.putText(img, text, (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2,
                    cv2.LINE_AA)
    return np.hstack([left, right])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m tools.figure', description=__doc__)
    parser.add_argument('--sequence', default='two_people')
    parser.add_argument('--frame', type=int, default=40)
    parser.add_argument('--out', default='docs/images/result_frame.png')
    args = parser.parse_args(argv)
    image = figure(args.sequence, args.frame)
    small = cv2.resize(image, (image.shape[1] * 3 // 4, image.shape[0] * 3 // 4),
                       interpolation=cv2.INTER_AREA)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(args.out, cv2.cvtColor(small, cv2.COLOR_RGB2BGR))
    print(args.out)
    return 0


if __name__ == '__main__':
    sys.exit(main())
