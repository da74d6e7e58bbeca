"""Readers of the two real depth sources: Skeltrack's test frames and PCL's ``five_people.pcd``.

Both are Kinect v1 recordings at 640x480. Each reader returns the source's depth as 16UC1
millimetres (0 = no reading), an RGB image (the source's colour, or a grey rendering of the
depth when it has none) and the pinhole intrinsics of the depth image.

Skeltrack (``tests/resources/depth-data-*``): 640 x 480 unsigned 16-bit values, row-major,
host byte order of the x86 machine that recorded them (little-endian), in millimetres: the
test program reads them into a ``guint16`` buffer of ``WIDTH * HEIGHT`` values, and its
example captures with ``GFREENECT_DEPTH_FORMAT_MM`` (libfreenect's ``FREENECT_DEPTH_MM``:
millimetres, not registered to the colour camera). Skeltrack itself projects with the
OpenKinect wiki's approximation (``x = (i - w/2) (z - 10) 0.0021 w/h``), which implies
non-square pixels (fx 357, fy 476) and is not a calibration; the frames are therefore given
libfreenect's own intrinsics of that depth mode, the IR camera's: fx = fy = 575.8 px (its
reference plane of 0.1042 mm pixels at 120 mm, at 640 px wide), principal point at the image
centre (320, 240), as ``freenect_camera_to_world`` uses.

PCL (``test/five_people.pcd``): an organised 640 x 480 cloud with fields ``x y z rgba``
(``DATA binary_compressed``: LZF-compressed, fields stored one after the other). ``z`` holds
whole millimetres (``mm * 0.001f``), NaN where there is no reading; the intrinsics are fitted
from ``x / z`` and ``y / z`` against the pixel columns and rows (:func:`fit_intrinsics`).
"""

from __future__ import annotations

import gzip
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from endeff_ros.core.types import Intrinsics

if TYPE_CHECKING:
    import numpy.typing as npt

WIDTH, HEIGHT = 640, 480
SKELTRACK_INTRINSICS = Intrinsics(575.8, 575.8, 320.0, 240.0, WIDTH, HEIGHT)
"""libfreenect's intrinsics of ``FREENECT_DEPTH_MM`` frames (see the module docstring)."""


class SourceError(ValueError):
    """A source file is not what its reader expects (the message names the file)."""


@dataclass(frozen=True)
class RealFrame:
    """One real frame: ``depth_mm`` (H, W) uint16 millimetres, 0 = no reading; ``rgb`` (H, W, 3)
    uint8; ``intrinsics`` of both (colour registered to depth)."""

    name: str
    depth_mm: npt.NDArray[np.uint16]
    rgb: npt.NDArray[np.uint8]
    intrinsics: Intrinsics


def depth_to_grey(depth_mm: npt.NDArray[np.uint16]) -> npt.NDArray[np.uint8]:
    """(H, W, 3) grey rendering of depth for sources without colour: near bright, far dark,
    no reading black (scaled between the 1st and 99th percentile of the valid depths)."""
    valid = depth_mm > 0
    grey = np.zeros(depth_mm.shape, np.uint8)
    if valid.any():
        lo, hi = np.percentile(depth_mm[valid], [1, 99])
        scaled = 1.0 - (depth_mm[valid] - lo) / max(hi - lo, 1.0)
        grey[valid] = np.clip(40 + 215 * scaled, 40, 255).astype(np.uint8)
    return np.repeat(grey[:, :, None], 3, axis=2)


def read_skeltrack(path: str | Path) -> RealFrame:
    """A Skeltrack depth frame (raw, or gzip-compressed when the name ends in ``.gz``)."""
    path = Path(path)
    raw = gzip.decompress(path.read_bytes()) if path.suffix == '.gz' else path.read_bytes()
    if len(raw) != WIDTH * HEIGHT * 2:
        msg = (f'{path}: {len(raw)} bytes, expected {WIDTH * HEIGHT * 2} (640 x 480 16-bit '
               f'depth values)')
        raise SourceError(msg)
    depth = np.frombuffer(raw, '<u2').reshape(HEIGHT, WIDTH).copy()
    name = path.name.removesuffix('.gz')
    return RealFrame(name, depth, depth_to_grey(depth), SKELTRACK_INTRINSICS)


def lzf_decompress(data: bytes, size: int) -> bytes:
    """LZF (liblzf, as PCL's ``binary_compressed``) decompression into ``size`` bytes.

    Literal runs and back-references are copied as slices; only overlapping references (runs
    repeating their own output) are copied byte by byte, as LZF defines them.
    """
    out = bytearray(size)
    ip = op = 0
    n = len(data)
    try:
        while ip < n:
            ctrl = data[ip]
            ip += 1
            if ctrl < 32:  # literal run of ctrl + 1 bytes
                length = ctrl + 1
                out[op:op + length] = data[ip:ip + length]
                ip += length
            else:  # back-reference
                length = ctrl >> 5
                ref = op - ((ctrl & 0x1F) << 8) - 1
                if length == 7:
                    length += data[ip]
                    ip += 1
                ref -= data[ip]
                ip += 1
                length += 2
                if ref < 0:
                    msg = 'back-reference before the start of the output'
                    raise SourceError(msg)
                if ref + length <= op:
                    out[op:op + length] = out[ref:ref + length]
                else:
                    for k in range(length):
                        out[op + k] = out[ref + k]
            op += length
    except IndexError as err:
        msg = 'truncated LZF data'
        raise SourceError(msg) from err
    if op != size:
        msg = f'LZF data decompressed to {op} bytes, the header says {size}'
        raise SourceError(msg)
    return bytes(out)


def read_pcd(path: str | Path) -> tuple[dict[str, str], dict[str, npt.NDArray[np.generic]]]:
    """``(header, fields)`` of a PCD v0.7 file with ``DATA binary_compressed`` or ``binary``.

    ``fields`` maps each field name to its (HEIGHT * WIDTH,) array (single-count fields only,
    which is what the organised clouds read here have).
    """
    path = Path(path)
    blob = path.read_bytes()
    header: dict[str, str] = {}
    pos = 0
    while 'DATA' not in header:
        end = blob.find(b'\n', pos)
        if end < 0:
            msg = f'{path}: no DATA line in the PCD header'
            raise SourceError(msg)
        line = blob[pos:end].decode('ascii', 'replace').strip()
        pos = end + 1
        if line and not line.startswith('#'):
            key, _, value = line.partition(' ')
            header[key] = value
    names = header.get('FIELDS', '').split()
    sizes = [int(s) for s in header.get('SIZE', '').split()]
    types = header.get('TYPE', '').split()
    counts = [int(c) for c in header.get('COUNT', ' '.join('1' * len(names))).split()]
    points = int(header.get('POINTS', '0'))
    if not names or not len(names) == len(sizes) == len(types) == len(counts) or \
            any(c != 1 for c in counts):
        msg = f'{path}: unsupported PCD fields {header.get("FIELDS")!r} (need single-count fields)'
        raise SourceError(msg)
    dtypes = [np.dtype(f'<{ {"F": "f", "U": "u", "I": "i"}[t]}{s}') for t, s in
              zip(types, sizes, strict=True)]
    mode = header['DATA']
    if mode == 'binary_compressed':
        compressed, size = struct.unpack('<II', blob[pos:pos + 8])
        try:
            data = lzf_decompress(blob[pos + 8:pos + 8 + compressed], size)
        except SourceError as err:
            raise SourceError(f'{path}: {err}') from err
        fields, offset = {}, 0
        for name, dt in zip(names, dtypes, strict=True):  # stored field after field
            fields[name] = np.frombuffer(data, dt, points, offset).copy()
            offset += dt.itemsize * points
    elif mode == 'binary':
        rec = np.dtype({'names': names, 'formats': dtypes})
        table = np.frombuffer(blob, rec, points, pos)
        fields = {name: table[name].copy() for name in names}
    else:
        msg = f'{path}: PCD DATA {mode!r} is not supported (binary or binary_compressed)'
        raise SourceError(msg)
    return header, fields


def fit_intrinsics(x: npt.ArrayLike, y: npt.ArrayLike, z: npt.ArrayLike
                   ) -> tuple[float, float, float, float]:
    """``(fx, fy, cx, cy)`` of an organised (H, W) cloud by least squares.

    A pinhole camera gives ``x / z = (u - cx) / fx`` per column u and ``y / z = (v - cy) / fy``
    per row v: two straight lines, fitted over the points with a reading.
    """
    x, y, z = (np.asarray(a, np.float64) for a in (x, y, z))
    v, u = np.indices(z.shape)
    ok = np.isfinite(x) & np.isfinite(y) & np.isfinite(z) & (z > 0)
    if np.count_nonzero(ok) < 3:
        msg = 'cannot fit intrinsics: fewer than 3 points with a reading'
        raise SourceError(msg)
    out = []
    for pix, ratio in ((u[ok], x[ok] / z[ok]), (v[ok], y[ok] / z[ok])):
        slope, offset = np.polyfit(pix.astype(np.float64), ratio, 1)
        out.append((1.0 / slope, -offset / slope))
    (fx, cx), (fy, cy) = out
    return float(fx), float(fy), float(cx), float(cy)


def read_five_people(path: str | Path) -> tuple[RealFrame, dict[str, npt.NDArray[np.generic]]]:
    """PCL's organised cloud as a registered depth + colour frame; also returns the cloud's
    fields reshaped to (H, W) (for checks against the source)."""
    header, fields = read_pcd(path)
    width, height = int(header.get('WIDTH', 0)), int(header.get('HEIGHT', 0))
    if not {'x', 'y', 'z', 'rgba'} <= set(fields) or height <= 1:
        msg = (f'{Path(path)}: need an organised cloud with x y z rgba, got fields '
               f'{sorted(fields)} and height {height}')
        raise SourceError(msg)
    grid = {k: v.reshape(height, width) for k, v in fields.items()}
    z = grid['z'].astype(np.float64)
    valid = np.isfinite(z) & (z > 0)
    depth = np.zeros((height, width), np.uint16)
    depth[valid] = np.round(z[valid] * 1000.0).astype(np.uint16)
    rgba = grid['rgba'].astype(np.uint32)
    rgb = np.stack([(rgba >> 16) & 255, (rgba >> 8) & 255, rgba & 255], axis=2).astype(np.uint8)
    fx, fy, cx, cy = fit_intrinsics(grid['x'], grid['y'], grid['z'])
    # The fit recovers the calibration to about 1e-5 px; round to what a driver would publish.
    intr = Intrinsics(round(fx, 3), round(fy, 3), round(cx, 3), round(cy, 3), width, height)
    return RealFrame(Path(path).stem, depth, rgb, intr), grid
