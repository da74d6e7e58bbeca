"""Measure the optical flow methods of :mod:`.flow` on synthetic pairs with known motion.

The paper's predict phase (Section 5.1) used LDOF; OpenCV offers DIS and Farneback. This module
builds 640x480 textured image pairs with ground-truth flow and reports the endpoint error (EPE,
pixels) and the single-thread time of each method, so the default is chosen from numbers:

- ``pan``: the whole textured scene translates (camera pan), flow is constant;
- ``blob_*``: a textured ellipse (a hand or a forearm) moves over a textured static background
  (a torso) by 2-25 px with up to 4 deg rotation and 4 % scale: a motion discontinuity. The
  background pixels the blob covers in the second frame are occluded and not scored.

Run ``python -m tools.flow_eval`` (add ``--json`` for the raw table). ``python -m tools.bench``
includes :func:`flow_benchmark`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from endeff_ros.core.flow import FlowEstimator

if TYPE_CHECKING:
    import numpy.typing as npt

WIDTH, HEIGHT = 640, 480

#: (name, tx px, ty px, rotation deg, scale) of the moving blob; ``pan`` moves everything.
CASES: tuple[tuple[str, float, float, float, float], ...] = (
    ('pan', 6.0, -3.0, 0.0, 1.0),
    ('blob_2px', 2.0, 1.0, 0.0, 1.0),
    ('blob_5px_rot', 5.0, -3.0, 2.0, 1.0),
    ('blob_10px_rot_scale', 10.0, 4.0, -3.0, 1.02),
    ('blob_15px_rot_scale', -15.0, -8.0, 4.0, 0.97),
    ('blob_25px_scale', 25.0, 6.0, -2.0, 1.04),
)

#: (method, scale) configurations measured by :func:`flow_benchmark`.
CONFIGS: tuple[tuple[str, float], ...] = (
    ('dis_ultrafast', 1.0), ('dis_ultrafast', 0.5),
    ('dis_fast', 1.0), ('dis_fast', 0.5),
    ('dis_medium', 1.0), ('dis_medium', 0.5),
    ('farneback', 1.0), ('farneback', 0.5),
)


@dataclass(frozen=True)
class FlowPair:
    """A synthetic image pair: (H, W, 3) uint8 RGB images, (H, W, 2) float32 ground-truth flow,
    (H, W) bool masks of the scored pixels and of the moving object (in the first image)."""

    name: str
    prev: npt.NDArray[np.uint8]
    cur: npt.NDArray[np.uint8]
    flow: npt.NDArray[np.float32]
    valid: npt.NDArray[np.bool_]
    obj: npt.NDArray[np.bool_]


def texture(rng: np.random.Generator, height: int, width: int) -> npt.NDArray[np.float32]:
    """(H, W, 3) float32 multi-scale noise texture in [0, 255] (cloth / skin-like detail)."""
    out = np.zeros((height, width, 3), np.float32)
    for sigma, weight in ((1.0, 0.5), (3.0, 1.0), (8.0, 1.0)):
        noise = rng.standard_normal((height, width, 3)).astype(np.float32)
        noise = cv2.GaussianBlur(noise, (0, 0), sigma)
        out += weight * noise / (noise.std() + 1e-6)
    out -= out.min()
    return out * (255.0 / out.max())


def make_pair(name: str, tx: float, ty: float, rot_deg: float, scale: float, *,
              seed: int = 0, noise: float = 2.0, width: int = WIDTH,
              height: int = HEIGHT) -> FlowPair:
    """Build one synthetic pair with exact flow (see :data:`CASES`); ``noise`` is sensor noise
    (grey levels, Gaussian sigma) added independently to both images."""
    rng = np.random.default_rng(seed)
    pad = 40
    canvas = texture(rng, height + 2 * pad, width + 2 * pad)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    if name == 'pan':
        prev = canvas[pad:pad + height, pad:pad + width]
        shift = np.float32([[1, 0, tx], [0, 1, ty]])
        big = cv2.warpAffine(canvas, shift, (width + 2 * pad, height + 2 * pad),
                             flags=cv2.INTER_LINEAR)
        cur = big[pad:pad + height, pad:pad + width]
        flow = np.dstack([np.full_like(xx, tx), np.full_like(yy, ty)])
        valid = ((xx + tx >= 0) & (xx + tx <= width - 1) & (yy + ty >= 0)
                 & (yy + ty <= height - 1))
        obj = np.zeros_like(valid)
    else:
        background = canvas[pad:pad + height, pad:pad + width]
        blob_tex = texture(rng, height, width)
        centre = (width * 0.45, height * 0.5)
        mask0 = np.zeros((height, width), np.float32)
        cv2.ellipse(mask0, (round(centre[0]), round(centre[1])), (80, 50), 20.0, 0, 360, 1.0,
                    -1, cv2.LINE_AA)
        affine = cv2.getRotationMatrix2D(centre, rot_deg, scale)
        affine[:, 2] += (tx, ty)
        mask1 = cv2.warpAffine(mask0, affine, (width, height), flags=cv2.INTER_LINEAR)
        tex1 = cv2.warpAffine(blob_tex, affine, (width, height), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REFLECT)
        prev = background * (1 - mask0[..., None]) + blob_tex * mask0[..., None]
        cur = background * (1 - mask1[..., None]) + tex1 * mask1[..., None]
        obj = mask0 > 0.5
        fx = affine[0, 0] * xx + affine[0, 1] * yy + affine[0, 2] - xx
        fy = affine[1, 0] * xx + affine[1, 1] * yy + affine[1, 2] - yy
        flow = np.dstack([np.where(obj, fx, 0.0), np.where(obj, fy, 0.0)])
        # Background pixels that the blob covers in the second image have no visible match.
        occluded = ~obj & (mask1 > 0.05)
        edge = (mask0 > 0.05) & (mask0 < 0.95)
        valid = ~occluded & ~edge
        valid &= (xx + flow[..., 0] >= 0) & (xx + flow[..., 0] <= width - 1)
        valid &= (yy + flow[..., 1] >= 0) & (yy + flow[..., 1] <= height - 1)
    prev = prev + rng.normal(0.0, noise, prev.shape)
    cur = cur + rng.normal(0.0, noise, cur.shape)
    return FlowPair(name, np.clip(prev, 0, 255).astype(np.uint8),
                    np.clip(cur, 0, 255).astype(np.uint8), flow.astype(np.float32),
                    valid, obj & valid)


def endpoint_error(estimate: npt.NDArray[np.float32], pair: FlowPair) -> tuple[float, float]:
    """Mean EPE (px) over the scored pixels, and over the moving object (NaN for a pan)."""
    epe = np.linalg.norm(estimate.astype(np.float64) - pair.flow, axis=2)
    obj = float(epe[pair.obj].mean()) if pair.obj.any() else float('nan')
    return float(epe[pair.valid].mean()), obj


def flow_benchmark(*, repeats: int = 5, seeds: int = 3,
                   configs: tuple[tuple[str, float], ...] = CONFIGS,
                   cases: tuple[tuple[str, float, float, float, float], ...] = CASES,
                   ) -> dict[str, Any]:
    """Accuracy and single-thread speed of each (method, scale) in ``configs``.

    Every case of ``cases`` is drawn with ``seeds`` different textures. Returns
    ``{'image': [W, H], 'threads': 1, 'cases': [...], 'rows': [...]}``; every row has
    ``method``, ``scale``, ``epe_mean`` (px, mean over pairs of the mean over scored pixels),
    ``epe_object`` (px, mean over the blob pairs at the moving object), ``epe_object_worst``
    (px, worst blob pair), ``epe_object_by_case`` (px, per blob case, mean over seeds) and
    ``time_ms`` (median of ``repeats`` calls of :meth:`.FlowEstimator.flow` on one core,
    grayscale conversion and resizing included).
    """
    pairs = [make_pair(*case, seed=100 * s + i) for s in range(max(1, seeds))
             for i, case in enumerate(cases)]
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    rows = []
    try:
        for method, scale in configs:
            est = FlowEstimator(method, scale=scale)
            epe_all, epe_obj = [], []
            by_case: dict[str, list[float]] = {}
            for pair in pairs:
                e_all, e_obj = endpoint_error(est.flow(pair.prev, pair.cur), pair)
                epe_all.append(e_all)
                if np.isfinite(e_obj):
                    epe_obj.append(e_obj)
                    by_case.setdefault(pair.name, []).append(e_obj)
            timing_pair = pairs[-1]
            times = []
            for _ in range(max(1, repeats)):
                t0 = time.perf_counter()
                est.flow(timing_pair.prev, timing_pair.cur)
                times.append((time.perf_counter() - t0) * 1e3)
            rows.append({
                'method': method, 'scale': scale,
                'epe_mean': round(float(np.mean(epe_all)), 3),
                'epe_object': round(float(np.mean(epe_obj)), 3) if epe_obj else None,
                'epe_object_worst': round(float(np.max(epe_obj)), 3) if epe_obj else None,
                'time_ms': round(float(np.median(times)), 2),
                'epe_object_by_case': {k: round(float(np.mean(v)), 2)
                                       for k, v in by_case.items()},
            })
    finally:
        cv2.setNumThreads(threads)
    return {'image': [WIDTH, HEIGHT], 'threads': 1, 'opencv': cv2.__version__,
            'cases': [c[0] for c in cases], 'seeds': max(1, seeds), 'rows': rows}


def format_table(result: dict[str, Any]) -> str:
    """The rows of :func:`flow_benchmark` as a text table."""
    rows = result['rows']
    cases = list(rows[0]['epe_object_by_case']) if rows else []
    lines = [f'{"method":16} {"scale":>5} {"EPE mean":>9} {"EPE obj":>8} {"obj worst":>9} '
             f'{"ms (1 th)":>9}   object EPE by case: {" ".join(cases)}']
    for row in rows:
        per_case = ' '.join(f'{row["epe_object_by_case"][c]:.2f}' for c in cases)
        lines.append(f'{row["method"]:16} {row["scale"]:5.2f} {row["epe_mean"]:9.2f} '
                     f'{row["epe_object"]:8.2f} {row["epe_object_worst"]:9.2f} '
                     f'{row["time_ms"]:9.2f}   {per_case}')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Print the flow benchmark table (or JSON with ``--json``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--json', action='store_true', help='print the raw result as JSON')
    parser.add_argument('--repeats', type=int, default=5, help='timing repeats per method')
    args = parser.parse_args(argv)
    result = flow_benchmark(repeats=args.repeats)
    print(json.dumps(result, indent=2) if args.json else format_table(result))
    return 0


if __name__ == '__main__':
    sys.exit(main())
