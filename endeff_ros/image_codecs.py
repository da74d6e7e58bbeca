"""Decode (and, for tests and tools, encode) ``sensor_msgs/CompressedImage`` payloads.

ROS-free: numpy and OpenCV only, so the bag reader, the node's converters and the tests share
one implementation. Formats are those written by ROS 2 ``image_transport_plugins``:

``compressed`` (``compressed_image_transport/src/compressed_publisher.cpp``)
    ``format = "<encoding>; jpeg compressed <target>"`` or ``"<encoding>; png compressed
    <target>"``. Colour images are converted to ``bgr8`` (``bgra8`` with alpha, ``bgr16`` for
    16 bit) before ``cv::imencode``, so the target names the channel order of the decoded
    array; grey images are ``mono8`` for JPEG and left as they are for PNG (the target is
    empty: ``"mono8; png compressed "``, ``"16UC1; png compressed "``). Formats without ``;``
    come from old publishers: 1 channel is mono, 3 are BGR (as the subscriber assumes).

``compressedDepth`` (``compressed_depth_image_transport/src/codec.cpp``,
``include/compressed_depth_image_transport/compression_common.hpp``)
    ``format = "<encoding>; compressedDepth png"`` (``"...; compressedDepth"`` from versions
    that only knew PNG, ``"...; compressedDepth rvl"`` for RVL). ``data`` starts with a 12-byte
    ``ConfigHeader``: ``int32 compressionFormat`` (``INV_DEPTH`` = 0) and ``float
    depthParam[2]``, native (little-endian) byte order, followed by a 16-bit PNG. ``16UC1``
    is stored as it is (values above ``depth_max`` set to 0). ``32FC1`` metres are stored as
    quantised inverse depth: with ``a = z0 (z0 + 1)`` and ``b = 1 - a / depth_max`` (``z0`` the
    ``depth_quantization`` parameter, default 100, ``depth_max`` default 10 m) the encoder
    writes ``uint16(a / d + b)`` (truncated; 0 for ``d >= depth_max`` and NaN) and the decoder
    reads ``d = a / (v - b)`` in float32, NaN where ``v == 0``. ``depthParam = (a, b)``.

Decoded depth follows ``depth_image_proc`` like raw images: ``16UC1`` is millimetres, ``32FC1``
metres; zero, negative and non-finite values become NaN (:func:`depth_to_metres`). Every
problem raises :class:`~endeff_ros.core.errors.InputError` naming the format.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from endeff_ros.core.errors import InputError

if TYPE_CHECKING:
    import numpy.typing as npt

#: ``compressionFormat`` of the compressedDepth ``ConfigHeader``.
INV_DEPTH = 0
#: ``ConfigHeader``: int32 format, float32 depthParam[2] (no padding: 3 x 4 bytes).
CONFIG_HEADER = np.dtype([('format', '<i4'), ('a', '<f4'), ('b', '<f4')])
#: Parameter defaults of compressed_depth_image_transport (metres; unitless).
DEFAULT_DEPTH_MAX = 10.0
DEFAULT_DEPTH_QUANTIZATION = 100.0

_COLOR_ENCODINGS = ('rgb8', 'bgr8', 'rgba8', 'bgra8', 'mono8')
_DEPTH_SCALE = {'16UC1': 1e-3, 'mono16': 1e-3, '32FC1': 1.0}


class CompressedFormat(NamedTuple):
    """A parsed ``CompressedImage.format``: original encoding, codec, and target of the codec.

    ``codec`` is ``'jpeg'``, ``'png'`` (compressed_image_transport), ``'compressedDepth png'``,
    ``'compressedDepth rvl'`` or ``''`` (no codec named: an old publisher).
    """

    encoding: str
    codec: str
    target: str


def parse_format(fmt: str) -> CompressedFormat:
    """Split ``"rgb8; jpeg compressed bgr8"`` into ``('rgb8', 'jpeg', 'bgr8')``."""
    text = str(fmt)
    if ';' not in text:
        # Old publishers wrote only the codec ("jpeg", "png") or nothing useful.
        return CompressedFormat('', text.strip().lower(), '')
    encoding, rest = (part.strip() for part in text.split(';', 1))
    words = rest.split()
    if words[:1] == ['compressedDepth']:
        kind = words[1] if len(words) > 1 else 'png'
        return CompressedFormat(encoding, f'compressedDepth {kind}', '')
    if len(words) >= 2 and words[1] == 'compressed':
        return CompressedFormat(encoding, words[0], words[2] if len(words) > 2 else '')
    msg = f'unknown compressed image format {text!r}'
    raise InputError(msg)


def as_uint8(data: Any) -> npt.NDArray[np.uint8]:
    """A message's ``data`` field as a flat uint8 array (no copy for numpy arrays from
    rosbags, ``bytes`` and ``array.array`` from rclpy)."""
    if isinstance(data, np.ndarray):
        return data.reshape(-1).view(np.uint8)
    try:
        return np.frombuffer(memoryview(data), dtype=np.uint8)
    except TypeError:
        return np.asarray(data, dtype=np.uint8).reshape(-1)


def _imdecode(buf: npt.NDArray[np.uint8], fmt: str) -> npt.NDArray[Any]:
    import cv2

    if buf.size == 0:
        msg = f'compressed image ({fmt!r}) has no data'
        raise InputError(msg)
    try:
        img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    except cv2.error as err:
        msg = f'cannot decode compressed image ({fmt!r}): {str(err).strip()}'
        raise InputError(msg) from err
    if img is None or img.size == 0:
        msg = f'cannot decode compressed image ({fmt!r}): not a valid JPEG/PNG payload'
        raise InputError(msg)
    return img


def decode_color(fmt: str, data: Any) -> npt.NDArray[np.uint8]:
    """``CompressedImage`` colour payload -> (H, W, 3) uint8 RGB.

    The decoded array has the channel order of the codec's target (``bgr8``/``bgra8``: BGR;
    ``rgb8``: RGB; none: as the original encoding); 1-channel images are replicated to grey.
    """
    parsed = parse_format(fmt)
    if parsed.codec not in ('jpeg', 'png', ''):
        msg = f'colour topic holds a {parsed.codec!r} image ({fmt!r}); expected jpeg or png'
        raise InputError(msg)
    if parsed.encoding and parsed.encoding not in _COLOR_ENCODINGS:
        msg = (f'unsupported compressed colour encoding {parsed.encoding!r} in {fmt!r} '
               f'(expected one of {", ".join(_COLOR_ENCODINGS)})')
        raise InputError(msg)
    img = _imdecode(as_uint8(data), fmt)
    if img.dtype != np.uint8:
        msg = f'compressed colour image ({fmt!r}) decodes to {img.dtype}, expected 8 bit'
        raise InputError(msg)
    if img.ndim == 2 or img.shape[2] == 1:
        return np.repeat(img.reshape(img.shape[0], img.shape[1], 1), 3, axis=2)
    order = parsed.target or parsed.encoding or 'bgr8'
    if order.startswith('rgb'):
        return np.ascontiguousarray(img[:, :, :3])
    return np.ascontiguousarray(img[:, :, 2::-1])  # BGR(A) -> RGB


def decode_depth_raw(fmt: str, data: Any) -> npt.NDArray[Any]:
    """``CompressedImage`` depth payload -> (H, W) array as the raw image held it.

    ``16UC1`` gives uint16 millimetres; ``32FC1`` (compressedDepth inverse depth) float32
    metres with NaN where nothing was stored.
    """
    parsed = parse_format(fmt)
    buf = as_uint8(data)
    if parsed.codec == 'compressedDepth rvl':
        msg = f'compressedDepth RVL ({fmt!r}) is not supported; record with png'
        raise InputError(msg)
    if parsed.codec.startswith('compressedDepth'):
        if buf.size <= CONFIG_HEADER.itemsize:
            msg = (f'compressedDepth image ({fmt!r}) has {buf.size} bytes: no room for the '
                   f'{CONFIG_HEADER.itemsize}-byte ConfigHeader and a PNG')
            raise InputError(msg)
        header = np.frombuffer(buf[:CONFIG_HEADER.itemsize].tobytes(), CONFIG_HEADER)[0]
        img = _imdecode(buf[CONFIG_HEADER.itemsize:], fmt)
        if parsed.encoding == '32FC1':
            if int(header['format']) != INV_DEPTH:
                msg = (f'compressedDepth image ({fmt!r}) has compressionFormat '
                       f'{int(header["format"])}, expected INV_DEPTH ({INV_DEPTH})')
                raise InputError(msg)
            return _inverse_depth(_single_u16(img, fmt), header['a'], header['b'])
    elif parsed.codec == 'png':
        img = _imdecode(buf, fmt)
    else:
        msg = (f'depth topic holds a {parsed.codec or "unknown"} image ({fmt!r}); expected '
               f'"16UC1; compressedDepth png", "32FC1; compressedDepth png" or "16UC1; png '
               f'compressed"')
        raise InputError(msg)
    if parsed.encoding not in ('16UC1', 'mono16'):
        msg = (f'unsupported compressed depth encoding {parsed.encoding!r} in {fmt!r} '
               f'(expected 16UC1 in millimetres or 32FC1 in metres)')
        raise InputError(msg)
    return _single_u16(img, fmt)


def _single_u16(img: npt.NDArray[Any], fmt: str) -> npt.NDArray[np.uint16]:
    if img.ndim != 2 or img.dtype != np.uint16:
        shape = 'x'.join(str(n) for n in img.shape)
        msg = (f'compressed depth image ({fmt!r}) decodes to {shape} {img.dtype}, expected '
               f'one 16-bit channel')
        raise InputError(msg)
    return img


def _inverse_depth(values: npt.NDArray[np.uint16], a: float, b: float
                   ) -> npt.NDArray[np.float32]:
    """``d = a / (v - b)`` in float32 as the C++ decoder computes it; NaN where ``v == 0``."""
    fa, fb = np.float32(a), np.float32(b)
    with np.errstate(divide='ignore', invalid='ignore'):
        depth = fa / (values.astype(np.float32) - fb)
    depth[values == 0] = np.nan
    return depth


def depth_to_metres(pixels: npt.NDArray[Any], encoding: str) -> npt.NDArray[np.float32]:
    """(H, W) depth of ``encoding`` (``16UC1`` mm, ``32FC1`` m) -> float32 metres, NaN = none.

    Integer millimetres: only 0 means no reading. Floating metres: zero, negative and
    non-finite values are no reading.
    """
    depth = pixels.astype(np.float32)
    scale = _DEPTH_SCALE[encoding]
    if scale != 1.0:
        depth *= np.float32(scale)
    if np.issubdtype(pixels.dtype, np.integer):
        depth[pixels == 0] = np.nan
    else:
        with np.errstate(invalid='ignore'):
            depth[~(depth > 0) | ~np.isfinite(depth)] = np.nan
    return depth


def decode_depth(fmt: str, data: Any) -> npt.NDArray[np.float32]:
    """``CompressedImage`` depth payload -> (H, W) float32 metres, NaN where no reading."""
    raw = decode_depth_raw(fmt, data)
    encoding = '32FC1' if raw.dtype == np.float32 else '16UC1'
    return depth_to_metres(raw, encoding)


# --------------------------------------------------------------------------------------------
# Encoders following image_transport_plugins (for tests and tools; byte layout as the C++)
# --------------------------------------------------------------------------------------------

def encode_color(image: npt.NDArray[np.uint8], encoding: str, codec: str = 'jpeg', *,
                 jpeg_quality: int = 95, png_level: int = 3) -> tuple[str, bytes]:
    """``(format, data)`` as compressed_image_transport publishes ``image`` of ``encoding``.

    ``image`` holds the channels in the order ``encoding`` names (as the raw message would).
    Colour is converted to BGR(A) first (the publisher's ``cv_bridge`` target), grey stays.
    Defaults are the plugin's (JPEG quality 95, PNG level 3).
    """
    import cv2

    if encoding not in _COLOR_ENCODINGS:
        msg = f'cannot encode colour encoding {encoding!r}'
        raise InputError(msg)
    if encoding == 'mono8':
        target, bgr = ('mono8' if codec == 'jpeg' else ''), image
    elif codec == 'png' and encoding in ('rgba8', 'bgra8'):
        target = 'bgra8'
        bgr = image if encoding == 'bgra8' else image[:, :, [2, 1, 0, 3]]
    else:
        target = 'bgr8'
        bgr = image[:, :, :3] if encoding.startswith('bgr') else image[:, :, 2::-1]
    bgr = np.ascontiguousarray(bgr)
    if codec == 'jpeg':
        ok, buf = cv2.imencode('.jpg', bgr, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
    elif codec == 'png':
        ok, buf = cv2.imencode('.png', bgr, [cv2.IMWRITE_PNG_COMPRESSION, int(png_level)])
    else:
        msg = f'unknown codec {codec!r} (jpeg or png)'
        raise InputError(msg)
    if not ok:
        msg = f'cv2.imencode failed for {encoding} {codec}'
        raise InputError(msg)
    return f'{encoding}; {codec} compressed {target}', buf.tobytes()


def encode_depth(depth: npt.NDArray[Any], encoding: str, transport: str = 'compressedDepth', *,
                 depth_max: float = DEFAULT_DEPTH_MAX,
                 depth_quantization: float = DEFAULT_DEPTH_QUANTIZATION,
                 png_level: int = 9) -> tuple[str, bytes]:
    """``(format, data)`` as image_transport publishes a raw depth image of ``encoding``.

    ``transport='compressedDepth'``: ConfigHeader + PNG of ``depth`` (``16UC1`` uint16 mm with
    values above ``depth_max`` zeroed, or ``32FC1`` float32 m quantised to inverse depth).
    ``transport='compressed'``: compressed_image_transport's PNG of a ``16UC1`` image, no
    header. Defaults are the plugins' (depth_max 10 m, quantization 100, PNG level 9 / 3).
    """
    import cv2

    header = np.zeros(1, CONFIG_HEADER)
    header['format'] = INV_DEPTH
    if transport == 'compressed':
        if encoding != '16UC1':
            msg = f'compressed_image_transport PNG depth needs 16UC1, not {encoding}'
            raise InputError(msg)
        ok, buf = cv2.imencode('.png', np.ascontiguousarray(depth, np.uint16),
                               [cv2.IMWRITE_PNG_COMPRESSION, 3])
        return '16UC1; png compressed ', buf.tobytes()
    if encoding == '32FC1':
        d = np.asarray(depth, np.float32)
        a = np.float32(depth_quantization) * (np.float32(depth_quantization) + np.float32(1))
        b = np.float32(1) - a / np.float32(depth_max)
        with np.errstate(divide='ignore', invalid='ignore'):
            inv = a / d + b
            # d < depth_max is False for NaN, as in the C++ comparison; d <= 0 (undefined
            # in the C++ cast) is stored as 0, no reading.
            keep = (d < np.float32(depth_max)) & (d > 0)
        img = np.where(keep, inv, 0).clip(0, 65535).astype(np.uint16)  # truncates as C++
        header['a'], header['b'] = a, b
    elif encoding == '16UC1':
        img = np.array(depth, np.uint16)
        img[img > np.uint16(depth_max * 1000.0)] = 0
    else:
        msg = f'compressedDepth needs 16UC1 or 32FC1, not {encoding}'
        raise InputError(msg)
    ok, buf = cv2.imencode('.png', img, [cv2.IMWRITE_PNG_COMPRESSION, int(png_level)])
    if not ok:
        msg = f'cv2.imencode failed for {encoding} compressedDepth'
        raise InputError(msg)
    return f'{encoding}; compressedDepth png', header.tobytes() + buf.tobytes()
