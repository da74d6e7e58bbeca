"""``python -m endeff_ros.realdata``: fetch the real frames, build the real-frame bags, render
frames for labelling, re-lift the labels after a pick was moved.

- ``fetch SOURCE [--from SRC] [--cache DIR]``: copy a source's frames and licence from its
  repository into the cache (see :mod:`endeff_ros.realdata.fetch`);
- ``build OUT [--sources a,b] [--storage mcap|sqlite3] [--repeat N | --still N]``: one bag
  per source, or with ``--still`` one per frame played still with per-copy sensor noise;
- ``render OUT``: per frame a PNG of the depth (or colour) with a pixel grid (lines every
  20 px, numbered every 100 px) and the labels (circle of radius ``r_px``, id);
- ``label``: recompute ``depth_m`` and ``xyz`` of every ``labels.yaml`` from its picks.

``build``, ``render`` and ``label`` read the frames from the cache (``--cache``, default
``data/realdata-cache``) and the labels from the package.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from endeff_ros.realdata import (
    DEFAULT_CACHE,
    SOURCES,
    build_bags,
    build_still_bags,
    source_labels,
)
from endeff_ros.realdata.labels import LabelError, read_labels, write_labels
from endeff_ros.realdata.sources import SourceError, depth_to_grey

LABELS_HEADER = """Hand labels of {source} (see docs/real-frames.md). Edit u, v, r_px (and add or
remove labels), then run `python -m endeff_ros.realdata label` to recompute depth_m and xyz:
depth_m is the median depth of the part's pixels, xyz the part's centre behind that surface
(head +0.09 m, hand and foot +0.04 m along the ray of (u, v)), in the optical frame, metres.
Ids: per person 0 head, 1 left hand, 2 right hand, 3 left foot, 4 right foot, +5 per person."""


def render(out_dir: Path, cache: Path = DEFAULT_CACHE) -> list[Path]:
    """PNGs of every frame with grid and labels, for picking and reviewing labels."""
    import cv2

    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for source in SOURCES.values():
        frames = source.frames(cache)
        labels = source_labels(source, frames)
        for frame in frames:
            img = np.ascontiguousarray(frame.rgb[:, :, ::-1])
            if source.name == 'skeltrack':
                img = np.ascontiguousarray(depth_to_grey(frame.depth_mm)[:, :, ::-1])
            h, w = img.shape[:2]
            for x in range(0, w, 20):
                cv2.line(img, (x, 0), (x, h - 1), (0, 0, 255) if x % 100 == 0 else (0, 110, 0))
            for y in range(0, h, 20):
                cv2.line(img, (0, y), (w - 1, y), (0, 0, 255) if y % 100 == 0 else (0, 110, 0))
            for c in range(0, max(w, h), 100):
                if c < w:
                    cv2.putText(img, str(c), (c + 2, 10), cv2.FONT_HERSHEY_SIMPLEX, 0.35,
                                (0, 0, 255), 1)
                if 0 < c < h:
                    cv2.putText(img, str(c), (2, c + 12), cv2.FONT_HERSHEY_SIMPLEX, 0.35,
                                (0, 0, 255), 1)
            for lab in labels.get(frame.name, []):
                cv2.circle(img, (lab.u, lab.v), lab.r_px, (0, 255, 255), 1)
                cv2.drawMarker(img, (lab.u, lab.v), (0, 255, 255), cv2.MARKER_CROSS, 8)
                cv2.putText(img, str(lab.id), (lab.u + lab.r_px + 2, lab.v),
                            cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 255, 255), 1)
            path = out_dir / f'{source.name}_{frame.name}.png'
            cv2.imwrite(str(path), img)
            written.append(path)
    return written


def relabel(cache: Path = DEFAULT_CACHE) -> list[Path]:
    """Recompute every labels file from its picks (in place)."""
    written = []
    for source in SOURCES.values():
        read_labels(source.labels_path)  # clear error before anything is written
        labels = source_labels(source, source.frames(cache))
        write_labels(source.labels_path, labels, LABELS_HEADER.format(source=source.name))
        written.append(source.labels_path)
    return written


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status."""
    parser = argparse.ArgumentParser(prog='python -m endeff_ros.realdata',
                                     description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest='command', required=True)
    f = sub.add_parser('fetch', help="copy a source's frames and licence into the cache")
    f.add_argument('source', choices=list(SOURCES))
    f.add_argument('--from', dest='src', default=None,
                   help='git URL, git directory or folder laid out like the repository '
                   "(default: the source's public repository)")
    b = sub.add_parser('build', help='write one benchmark bag per source')
    b.add_argument('out', type=Path, help='output folder (bags are replaced)')
    b.add_argument('--sources', default=','.join(SOURCES),
                   help=f'comma-separated sources (default {",".join(SOURCES)})')
    b.add_argument('--storage', choices=('mcap', 'sqlite3'), default='mcap')
    b.add_argument('--repeat', type=int, default=1, metavar='N',
                   help='write every frame N times in a row (a still scene; default 1)')
    b.add_argument('--still', type=int, default=0, metavar='N',
                   help='one bag per frame, N copies each with per-copy sensor noise: '
                   'people still from the first frame (default 0: off)')
    r = sub.add_parser('render', help='PNG per frame with pixel grid and labels')
    r.add_argument('out', type=Path)
    la = sub.add_parser('label', help="recompute the labels' depth and xyz from their picks")
    for p in (f, b, r, la):
        p.add_argument('--cache', type=Path, default=DEFAULT_CACHE,
                       help=f'frame cache (default {DEFAULT_CACHE})')
    args = parser.parse_args(argv)
    try:
        if args.command == 'fetch':
            from endeff_ros.realdata.fetch import run
            return run(args.source, args.src, args.cache)
        if args.command == 'build':
            names = [s for s in args.sources.split(',') if s]
            if args.still:
                paths = build_still_bags(args.out, args.still, names=names, cache=args.cache,
                                         storage=args.storage)
            else:
                paths = build_bags(args.out, names=names, cache=args.cache,
                                   storage=args.storage, repeat=args.repeat)
        elif args.command == 'render':
            paths = render(args.out, args.cache)
        else:
            paths = relabel(args.cache)
    except (SourceError, LabelError, ValueError, OSError) as err:
        print(f'realdata {args.command}: {err}', file=sys.stderr)
        return 1
    for p in paths:
        print(p)
    return 0


if __name__ == '__main__':
    sys.exit(main())
