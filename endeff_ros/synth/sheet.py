"""``endeff sheet``: a contact sheet (PNG) of benchmark bags, so a person can look at the data.

One row per bag: for a few evenly spaced depth frames, the depth image (colour-mapped, 1.5 to
5.7 m, black = no reading) and the nearest colour image, both with the ground-truth
end-effectors of that frame drawn (circle + id). Works on any bag in the benchmark form, not
only the synthetic ones; directories are searched for bags (one copy per bag name, mcap first).

``--tiles`` draws one small tile per bag instead (the middle frame's colour image with the
ground truth and a depth inset), captioned with the bag's name and the attributes it records
in its metadata: a whole suite on one page.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

DEPTH_TOPIC = '/camera/depth/image_raw'
COLOR_TOPIC = '/camera/color/image_raw'
INFO_TOPIC = '/camera/depth/camera_info'
GT_TOPIC = '/ground_truth/end_effectors'
DEPTH_RANGE = (1.5, 5.7)  # m, colour-map range (near = red)
_ID_COLORS = [(0, 255, 255), (0, 255, 0), (255, 0, 255), (255, 128, 0), (0, 128, 255),
              (255, 255, 255), (128, 255, 128), (255, 128, 255), (255, 200, 100),
              (100, 200, 255)]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('bags', nargs='+', type=Path, help='bag directories or folders of bags')
    parser.add_argument('--out', required=True, type=Path, help='PNG file to write')
    parser.add_argument('--frames', type=int, default=4, help='frames per bag (default 4)')
    parser.add_argument('--scale', type=float, default=0.4,
                        help='tile size relative to the image (default 0.4)')
    parser.add_argument('--tiles', action='store_true',
                        help='one captioned tile per bag (middle frame) instead of rows')
    parser.add_argument('--cols', type=int, default=6, help='tiles per row (default 6)')
    parser.add_argument('--tile-width', type=int, default=300,
                        help='tile width in pixels (default 300)')


def find_bags(paths: list[Path]) -> list[Path]:
    """Bag directories (holding ``metadata.yaml``) under ``paths``; one per name, mcap first,
    the synthetic sequences in their standard order."""
    found: dict[str, Path] = {}
    for p in paths:
        cands = [p] if (p / 'metadata.yaml').exists() else sorted(
            q.parent for q in p.rglob('metadata.yaml'))
        cands.sort(key=lambda q: ('mcap' not in q.parts, str(q)))
        for q in cands:
            found.setdefault(q.name, q)
    from .sequences import SEQUENCES

    rank = {n: i for i, n in enumerate(SEQUENCES)}
    return sorted(found.values(), key=lambda q: (rank.get(q.name, len(rank)), q.name))


def _image(msg) -> npt.NDArray:
    """sensor_msgs/Image -> (H, W, 3) uint8 BGR or (H, W) float32 metres (NaN = none)."""
    h, w, enc = msg.height, msg.width, msg.encoding
    buf = np.asarray(msg.data, dtype=np.uint8)
    if enc in ('rgb8', 'bgr8'):
        img = buf.reshape(h, msg.step)[:, :w * 3].reshape(h, w, 3)
        return img[..., ::-1].copy() if enc == 'rgb8' else img.copy()
    if enc == '16UC1':
        dt = '>u2' if msg.is_bigendian else '<u2'
        mm = buf.reshape(h, msg.step)[:, :w * 2].copy().view(dt).astype(np.float32)
        return np.where(mm > 0, mm / 1000.0, np.nan).astype(np.float32)
    if enc == '32FC1':
        dt = '>f4' if msg.is_bigendian else '<f4'
        d = buf.reshape(h, msg.step)[:, :w * 4].copy().view(dt).astype(np.float32)
        return np.where(d > 0, d, np.nan).astype(np.float32)
    msg_ = f'unsupported image encoding {enc!r}'
    raise ValueError(msg_)


def _cloud(msg) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Ground-truth PointCloud2 -> (N, 3) positions and (N,) ids."""
    off = {f.name: f.offset for f in msg.fields}
    n = msg.width * msg.height
    buf = np.asarray(msg.data, dtype=np.uint8).reshape(n, msg.point_step)
    xyz = np.stack([buf[:, off[k]:off[k] + 4].copy().view('<f4')[:, 0] for k in 'xyz'], 1)
    ids = (buf[:, off['id']:off['id'] + 4].copy().view('<u4')[:, 0] if 'id' in off
           else np.arange(n))
    return xyz.astype(np.float64), ids.astype(np.int64)


def read_samples(bag: Path, n: int) -> list[dict]:
    """``n`` evenly spaced depth frames of ``bag`` with nearest colour, K and ground truth."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        conns = {c.topic: c for c in reader.connections}
        if DEPTH_TOPIC not in conns:
            return []
        depth_raw, color_raw, gts, info = [], [], {}, None
        for c, _, raw in reader.messages(connections=list(conns.values())):
            if c.topic == DEPTH_TOPIC:
                depth_raw.append((c, raw))
            elif c.topic == COLOR_TOPIC:
                color_raw.append((c, raw))
            elif c.topic == INFO_TOPIC and info is None:
                info = reader.deserialize(raw, c.msgtype)
            elif c.topic == GT_TOPIC:
                m = reader.deserialize(raw, c.msgtype)
                gts[m.header.stamp.sec * 10**9 + m.header.stamp.nanosec] = _cloud(m)
        pick = np.unique(np.linspace(0, len(depth_raw) - 1, n).round().astype(int))
        stamp = lambda m: m.header.stamp.sec * 10**9 + m.header.stamp.nanosec  # noqa: E731
        cstamps = []
        for c, raw in color_raw:  # colour stamps only (cheap header read)
            cstamps.append(stamp(reader.deserialize(raw, c.msgtype)))
        out = []
        for k in pick:
            dmsg = reader.deserialize(depth_raw[k][1], depth_raw[k][0].msgtype)
            t = stamp(dmsg)
            col = None
            if cstamps:
                j = int(np.argmin(np.abs(np.asarray(cstamps) - t)))
                c, raw = color_raw[j]
                col = _image(reader.deserialize(raw, c.msgtype))
            out.append({'index': int(k), 'stamp': t, 'depth': _image(dmsg), 'color': col,
                        'k': None if info is None else np.asarray(info.k, float).reshape(3, 3),
                        'gt': gts.get(t), 'encoding': dmsg.encoding})
        return out


def _draw_gt(img: npt.NDArray[np.uint8], k: npt.NDArray | None, gt, scale: float) -> None:
    if gt is None or k is None:
        return
    pts, ids = gt
    for p, i in zip(pts, ids):
        if p[2] <= 0:
            continue
        u = (k[0, 0] * p[0] / p[2] + k[0, 2]) * scale
        v = (k[1, 1] * p[1] / p[2] + k[1, 2]) * scale
        col = _ID_COLORS[int(i) % len(_ID_COLORS)]
        cv2.circle(img, (int(round(u)), int(round(v))), 5, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.circle(img, (int(round(u)), int(round(v))), 5, col, 2, cv2.LINE_AA)
        cv2.putText(img, str(int(i)), (int(u) + 6, int(v) - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                    col, 1, cv2.LINE_AA)


def _depth_vis(depth: npt.NDArray[np.float32]) -> npt.NDArray[np.uint8]:
    d = np.nan_to_num(depth, nan=0.0)
    norm = np.clip((d - DEPTH_RANGE[0]) / (DEPTH_RANGE[1] - DEPTH_RANGE[0]), 0, 1)
    vis = cv2.applyColorMap((255 - norm * 255).astype(np.uint8), cv2.COLORMAP_TURBO)
    vis[d <= 0] = 0
    return vis


def contact_sheet(bags: list[Path], n_frames: int = 4, scale: float = 0.4
                  ) -> npt.NDArray[np.uint8]:
    """The sheet as a BGR image (H, W, 3) uint8."""
    rows = []
    for bag in bags:
        samples = read_samples(bag, n_frames)
        if not samples:
            continue
        tiles = []
        for s in samples:
            h, w = s['depth'].shape
        tw, th = int(round(w * scale)), int(round(h * scale))
        for s in samples:
            dv = cv2.resize(_depth_vis(s['depth']), (tw, th), interpolation=cv2.INTER_NEAREST)
            cv = (cv2.resize(s['color'], (tw, th), interpolation=cv2.INTER_AREA)
                  if s['color'] is not None else np.zeros((th, tw, 3), np.uint8))
            for img in (dv, cv):
                _draw_gt(img, s['k'], s['gt'], scale)
            cv2.putText(dv, f"#{s['index']} {s['encoding']}", (4, th - 6),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
            tiles += [dv, cv]
        row = np.concatenate(tiles, 1)
        label = np.full((22, row.shape[1], 3), 40, np.uint8)
        cv2.putText(label, f'{bag.name}  ({bag})', (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    (255, 255, 255), 1, cv2.LINE_AA)
        rows.append(np.concatenate([label, row], 0))
    if not rows:
        msg = 'no bags with a depth topic found'
        raise ValueError(msg)
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 2), (0, width - r.shape[1]), (0, 0))) for r in rows]
    return np.concatenate(rows, 0)


def bag_attributes(bag: Path) -> dict:
    """The attributes a bag records in its rosbag2 metadata (``{}`` if none or unreadable)."""
    from rosbags.highlevel import AnyReader

    from ..attributes import custom_data, parse_attributes

    with AnyReader([bag]) as reader:
        attrs, _ = parse_attributes(custom_data(reader), bag.name)
    return attrs


def attribute_line(attrs: dict) -> str:
    """A short caption of the main attributes, e.g. ``side 2.4m cam1.2m d435 wall p1 cut``."""
    if not attrs:
        return ''
    parts = [str(attrs.get('view', '')), f"{attrs.get('distance_m', 0):.1f}m",
             f"cam{attrs.get('camera_height_m', 0):.1f}m", str(attrs.get('sensor', '')),
             str(attrs.get('room', '')), f"p{attrs.get('people', '')}"]
    if attrs.get('interaction', 'none') != 'none':
        parts.append(str(attrs['interaction']))
    if attrs.get('truncated'):
        parts.append('cut')
    return ' '.join(p for p in parts if p)


def tile_sheet(bags: list[Path], cols: int = 6, tile_w: int = 300) -> npt.NDArray[np.uint8]:
    """One tile per bag (middle frame: colour with ground truth, depth inset in the corner,
    name and attribute line below), ``cols`` per row, ``tile_w`` px wide; BGR (H, W, 3)."""
    tiles = []
    for bag in bags:
        samples = read_samples(bag, 3)
        if not samples:
            continue
        s = samples[len(samples) // 2]
        h, w = s['depth'].shape
        scale = tile_w / w
        th = int(round(h * scale))
        img = (cv2.resize(s['color'], (tile_w, th), interpolation=cv2.INTER_AREA)
               if s['color'] is not None else np.zeros((th, tile_w, 3), np.uint8))
        _draw_gt(img, s['k'], s['gt'], scale)
        inset = cv2.resize(_depth_vis(s['depth']), (tile_w // 3, th // 3),
                           interpolation=cv2.INTER_NEAREST)
        img[:inset.shape[0], -inset.shape[1]:] = inset
        cap = np.full((30, tile_w, 3), 40, np.uint8)
        chars = tile_w * 52 // 300
        for row, text in enumerate((bag.name[:chars], attribute_line(bag_attributes(bag)))):
            cv2.putText(cap, text, (3, 12 + 14 * row), cv2.FONT_HERSHEY_SIMPLEX, 0.33,
                        (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(np.concatenate([img, cap], 0))
    if not tiles:
        msg = 'no bags with a depth topic found'
        raise ValueError(msg)
    th = max(t.shape[0] for t in tiles)
    tiles = [np.pad(t, ((0, th - t.shape[0] + 2), (0, 2), (0, 0))) for t in tiles]
    tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % cols)
    rows = [np.concatenate(tiles[k:k + cols], 1) for k in range(0, len(tiles), cols)]
    return np.concatenate(rows, 0)


def run(args: argparse.Namespace) -> int:
    bags = find_bags(args.bags)
    if not bags:
        print(f'endeff sheet: no rosbag2 bags found in {", ".join(map(str, args.bags))}',
              file=sys.stderr)
        return 2
    try:
        if getattr(args, 'tiles', False):
            sheet = tile_sheet(bags, max(1, getattr(args, 'cols', 6)),
                               max(120, getattr(args, 'tile_width', 300)))
        else:
            sheet = contact_sheet(bags, args.frames, args.scale)
    except ValueError as exc:
        print(f'endeff sheet: {exc}', file=sys.stderr)
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(args.out), sheet, [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        print(f'endeff sheet: could not write {args.out}', file=sys.stderr)
        return 1
    print(f'wrote {args.out} ({sheet.shape[1]}x{sheet.shape[0]}, {len(bags)} bags)')
    return 0
