"""endeff_ros.image_codecs against image_transport's byte layout (encoder and decoder)."""

from __future__ import annotations

import struct

import cv2
import numpy as np
import pytest

from endeff_ros import image_codecs as codecs
from endeff_ros.core.errors import InputError

RNG = np.random.default_rng(7)


def _rgb(h: int = 24, w: int = 32) -> np.ndarray:
    """A smooth image (JPEG-friendly) with distinct channels."""
    y, x = np.mgrid[0:h, 0:w]
    return np.stack([8 * x, 10 * y, 255 - 6 * x], axis=2).clip(0, 255).astype(np.uint8)


@pytest.mark.parametrize(('fmt', 'want'), [
    ('rgb8; jpeg compressed bgr8', ('rgb8', 'jpeg', 'bgr8')),
    ('bgr8; png compressed bgr8', ('bgr8', 'png', 'bgr8')),
    ('mono8; png compressed ', ('mono8', 'png', '')),
    ('16UC1; compressedDepth png', ('16UC1', 'compressedDepth png', '')),
    ('16UC1; compressedDepth', ('16UC1', 'compressedDepth png', '')),
    ('32FC1; compressedDepth rvl', ('32FC1', 'compressedDepth rvl', '')),
    ('jpeg', ('', 'jpeg', '')),
])
def test_parse_format(fmt: str, want: tuple[str, str, str]) -> None:
    assert tuple(codecs.parse_format(fmt)) == want


@pytest.mark.parametrize('encoding', ['rgb8', 'bgr8', 'rgba8', 'bgra8'])
def test_png_colour_is_lossless(encoding: str) -> None:
    rgb = RNG.integers(0, 256, (12, 16, 3), dtype=np.uint8)
    order = [2, 1, 0] if encoding.startswith('bgr') else [0, 1, 2]
    raw = rgb[:, :, order]
    if encoding.endswith('a8'):
        raw = np.concatenate([raw, np.full((12, 16, 1), 200, np.uint8)], axis=2)
    fmt, data = codecs.encode_color(raw, encoding, 'png')
    assert fmt == f'{encoding}; png compressed {"bgra8" if encoding.endswith("a8") else "bgr8"}'
    # The payload is a PNG whose channels are in the target (BGR) order, as cv::imencode saw.
    stored = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(stored[:, :, :3], rgb[:, :, ::-1])
    np.testing.assert_array_equal(codecs.decode_color(fmt, data), rgb)


def test_jpeg_colour_within_tolerance_and_channel_order() -> None:
    rgb = _rgb()
    fmt, data = codecs.encode_color(rgb, 'rgb8', 'jpeg')
    assert fmt == 'rgb8; jpeg compressed bgr8' and data[:2] == b'\xff\xd8'
    out = codecs.decode_color(fmt, np.frombuffer(data, np.uint8))  # rosbags gives uint8 arrays
    assert out.shape == rgb.shape and out.dtype == np.uint8
    assert np.abs(out.astype(int) - rgb).mean() < 3.0
    swapped = codecs.decode_color('rgb8; jpeg compressed rgb8', data)  # target says RGB
    assert np.abs(swapped.astype(int) - rgb[:, :, ::-1]).mean() < 3.0


def test_mono_colour_is_replicated() -> None:
    grey = RNG.integers(0, 256, (10, 14), dtype=np.uint8)
    fmt, data = codecs.encode_color(grey, 'mono8', 'png')
    assert fmt == 'mono8; png compressed '
    np.testing.assert_array_equal(codecs.decode_color(fmt, data), np.stack([grey] * 3, axis=2))
    fmt, data = codecs.encode_color(grey, 'mono8', 'jpeg')
    assert fmt == 'mono8; jpeg compressed mono8'
    assert np.abs(codecs.decode_color(fmt, data)[:, :, 1].astype(int) - grey).mean() < 20


def test_compressed_depth_16uc1_header_and_lossless() -> None:
    mm = RNG.integers(0, 12_000, (20, 30)).astype(np.uint16)
    fmt, data = codecs.encode_depth(mm, '16UC1')
    assert fmt == '16UC1; compressedDepth png'
    # ConfigHeader: int32 INV_DEPTH (0), float depthParam[2] (unused for 16UC1: zeros), PNG.
    assert struct.unpack('<iff', data[:12]) == (0, 0.0, 0.0)
    assert data[12:20] == b'\x89PNG\r\n\x1a\n'
    raw = codecs.decode_depth_raw(fmt, data)
    want = np.where(mm > 10_000, 0, mm)  # above depth_max (10 m) the publisher stores 0
    np.testing.assert_array_equal(raw, want)
    metres = codecs.decode_depth(fmt, data)
    np.testing.assert_array_equal(np.isnan(metres), want == 0)
    np.testing.assert_allclose(metres[want > 0], want[want > 0] * 1e-3, rtol=1e-6)
    # Old publishers wrote no codec after "compressedDepth": PNG.
    np.testing.assert_array_equal(codecs.decode_depth_raw('16UC1; compressedDepth', data), want)


def test_compressed_depth_32fc1_inverse_depth() -> None:
    d = RNG.uniform(0.4, 12.0, (20, 30)).astype(np.float32)
    d[0, :3] = (np.nan, 0.0, np.inf)
    fmt, data = codecs.encode_depth(d, '32FC1')
    assert fmt == '32FC1; compressedDepth png'
    a, b = 100.0 * 101.0, 1.0 - 100.0 * 101.0 / 10.0
    kind, pa, pb = struct.unpack('<iff', data[:12])
    assert kind == 0 and pa == pytest.approx(a) and pb == pytest.approx(b)
    stored = cv2.imdecode(np.frombuffer(data[12:], np.uint8), cv2.IMREAD_UNCHANGED)
    assert stored.dtype == np.uint16
    out = codecs.decode_depth(fmt, data)
    # Exactly the C++ decoder's float arithmetic on the stored values ...
    with np.errstate(divide='ignore'):
        want = np.float32(pa) / (stored.astype(np.float32) - np.float32(pb))
    want[stored == 0] = np.nan
    want[~(want > 0)] = np.nan
    np.testing.assert_array_equal(out, want)
    # ... and within the quantisation step of the input (d^2 / a per unit) below depth_max.
    ok = np.isfinite(d) & (d > 0) & (d < 10.0)
    assert np.all(np.isnan(out[~ok]))
    np.testing.assert_allclose(out[ok], d[ok], atol=0, rtol=0.0105)


def test_png_compressed_16uc1_without_header() -> None:
    mm = RNG.integers(0, 65_535, (9, 11)).astype(np.uint16)
    fmt, data = codecs.encode_depth(mm, '16UC1', 'compressed')
    assert fmt == '16UC1; png compressed ' and data[:8] == b'\x89PNG\r\n\x1a\n'
    np.testing.assert_array_equal(codecs.decode_depth_raw(fmt, data), mm)


@pytest.mark.parametrize(('fmt', 'data', 'pattern'), [
    ('16UC1; compressedDepth rvl', b'\0' * 40, 'RVL'),
    ('16UC1; compressedDepth png', b'\0' * 12, 'ConfigHeader'),
    ('16UC1; compressedDepth png', b'\0' * 12 + b'not a png', 'cannot decode'),
    ('rgb8; jpeg compressed bgr8', b'', 'no data'),
    ('8UC3; png compressed bgr8', b'x', 'unsupported compressed colour encoding'),
    ('rgb8; tiff compressed', b'x', 'expected jpeg or png'),
    ('rgb8; h264', b'x', 'unknown compressed image format'),
])
def test_bad_payloads_raise_input_error(fmt: str, data: bytes, pattern: str) -> None:
    decode = codecs.decode_depth if 'UC1' in fmt else codecs.decode_color
    with pytest.raises(InputError, match=pattern):
        decode(fmt, data)


def test_depth_of_wrong_kind() -> None:
    fmt, data = codecs.encode_color(_rgb(), 'rgb8', 'png')
    with pytest.raises(InputError, match='expected'):
        codecs.decode_depth(fmt, data)
    with pytest.raises(InputError, match='one 16-bit channel'):
        codecs.decode_depth('16UC1; png compressed ', data)
