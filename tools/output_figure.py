"""The picture of docs/output.md: what RViz2 with config/endeff.rviz shows, drawn without RViz.

RViz2 is not on PyPI, so a venv cannot show it; this draws the same content on one frame of
a bag, seen from the camera: the depth image (near = bright), the bands coloured by sub-band
(``debug/bands``) and each published end-effector with its path to the root and its marker
label (``hand 7``: :func:`endeff_ros.ros.convert.draw_tracks`). The tracker runs from the
bag's first frame, as the node would (:func:`tools.frame_view.run_to_frame`).

    python -m tools.output_figure [BAG] [--frame N] [--out docs/images/output_labels.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from endeff_ros.ros.convert import depth_to_rgb, draw_tracks, palette
from tools.frame_view import run_to_frame

DEFAULT_BAG = Path('data/synth/mcap/two_people')


def draw(bag: Path, frame: int) -> npt.NDArray[np.uint8]:
    """(H, W, 3) RGB picture of ``frame`` of ``bag`` (see the module docstring)."""
    f, _, result = run_to_frame(bag, frame)
    est = result.estimate
    img = depth_to_rgb(f.depth)
    keep = est.subband >= 0
    if keep.any():
        bands = img.copy()
        uv = np.round(f.intrinsics.project(est.points[keep])).astype(np.int32)
        colours = palette(est.subband[keep])
        for (u, v), c in zip(uv, colours):
            cv2.circle(bands, (int(u), int(v)), 2, tuple(int(x) for x in c), -1)
        img = cv2.addWeighted(bands, 0.55, img, 0.45, 0.0)  # the labels stand out
    return draw_tracks(img, f.intrinsics, result.tracks)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m tools.output_figure',
                                     description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', nargs='?', type=Path, default=DEFAULT_BAG)
    parser.add_argument('--frame', type=int, default=40)
    parser.add_argument('--out', type=Path, default=Path('docs/images/output_labels.png'))
    args = parser.parse_args(argv)
    img = draw(args.bag, args.frame)
    img = cv2.resize(img, None, fx=1.5, fy=1.5, interpolation=cv2.INTER_LINEAR)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out), img[:, :, ::-1])
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
