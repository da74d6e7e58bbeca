"""``python -m tools.bench``: timing benchmarks, printed and written as JSON.

- ``single_frame_ms``: Sections 3-4 (:func:`estimate_frame`) on one synthetic 640x480 frame of a
  standing person (~25 k foreground pixels at ~2.8 m), with per-stage medians in
  ``stages_ms``. Optical flow is not included.
- ``full_pipeline_ms``: the predict-update :class:`Tracker` per 640x480 frame of a synthetic
  sequence, optical flow included (``full_stages_ms`` per stage).
- optional: ``flow`` (optical-flow methods table), ``process`` (offline bag throughput; its
  ``whole_command`` times ``endeff process`` end to end on a 300-frame bag on the same core,
  with ``ratio_to_full_pipeline``: its frames/s over those the full-pipeline median allows),
  ``ros`` (end-to-end DDS latency against a relay node).

Everything runs on one core: the process pins itself to a single CPU and OpenCV to one thread,
so the figures are what a robot can expect from one core.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

from endeff_ros.cli_common import load_params_option, print_json


def _pin_one_core() -> int | None:
    """Pin this process (and its threads) to one CPU; returns the CPU or None if unsupported."""
    try:
        cpu = sorted(os.sched_getaffinity(0))[-1]
        os.sched_setaffinity(0, {cpu})
    except (AttributeError, OSError):
        return None
    import cv2

    cv2.setNumThreads(1)
    return cpu


@contextlib.contextmanager
def _all_cores() -> Iterator[None]:
    """Temporarily allow every CPU (child processes inherit the affinity)."""
    pinned = os.sched_getaffinity(0) if hasattr(os, 'sched_getaffinity') else None
    try:
        if pinned is not None:
            os.sched_setaffinity(0, set(range(os.cpu_count() or 1)))
        yield
    finally:
        if pinned is not None:
            os.sched_setaffinity(0, pinned)


def _stats(samples: list[float]) -> dict[str, float]:
    a = np.asarray(samples)
    return {'median': round(float(np.median(a)), 3), 'p95': round(float(np.percentile(a, 95)), 3),
            'mean': round(float(a.mean()), 3), 'n': int(a.size)}


def bench_single_frame(repeats: int = 200, warmup: int = 10,
                       params: Any = None) -> dict[str, Any]:
    """Time :func:`estimate_frame` on one standing-person frame."""
    from endeff_ros.core.params import EndeffParams
    from endeff_ros.core.single_frame import estimate_frame
    from endeff_ros.core.types import RGBDFrame
    from endeff_ros.synth import render_person_frame

    f = render_person_frame()
    frame = RGBDFrame(f.stamp_ns, f.frame_id, f.depth, f.intrinsics, f.color)
    params = params or EndeffParams()
    box = np.isfinite(f.depth) & (f.depth >= params.box_min_z) & (f.depth <= params.box_max_z)
    for _ in range(warmup):
        estimate_frame(frame, params)
    times, stages = [], {}
    for _ in range(repeats):
        t0 = time.perf_counter()
        est = estimate_frame(frame, params)
        times.append((time.perf_counter() - t0) * 1e3)
        for k, v in est.stage_ms.items():
            stages.setdefault(k, []).append(v)
    return {'single_frame_ms': _stats(times),
            'stages_ms': {k: round(float(np.median(v)), 3) for k, v in stages.items()},
            'frame': {'width': f.intrinsics.width, 'height': f.intrinsics.height,
                      'valid_depth_pixels': int(np.isfinite(f.depth).sum()),
                      'pixels_in_depth_range': int(box.sum()),
                      'foreground_pixels': _foreground_pixels(frame, params),
                      'foreground_points': len(est.points),
                      'end_effectors': len(est.positions())}}


def _foreground_pixels(frame: Any, params: Any) -> int:
    """Pixels left after the box and the floor removal at full resolution (Section 3)."""
    from endeff_ros.core.cloud import foreground_cloud

    full = params.replace(pixel_stride=1, voxel_size=0.0)
    return len(foreground_cloud(frame.depth, frame.intrinsics, full).points)


def bench_full_pipeline(sequence: str = 'waving_two_hands', repeats: int = 2,
                        params: Any = None) -> dict[str, Any]:
    """Time :meth:`Tracker.update` per frame over a synthetic sequence, flow included."""
    from endeff_ros.core.params import EndeffParams
    from endeff_ros.core.tracker import Tracker
    from endeff_ros.core.types import RGBDFrame
    from endeff_ros.synth import render_sequence

    frames = [RGBDFrame(f.stamp_ns, f.frame_id, f.depth, f.intrinsics, f.color)
              for f in render_sequence(sequence) if f.depth is not None]
    times, stages = [], {}
    for r in range(repeats):
        tracker = Tracker(params or EndeffParams())
        for frame in frames:
            t0 = time.perf_counter()
            res = tracker.update(frame)
            dt = (time.perf_counter() - t0) * 1e3
            if r or frame is not frames[0]:  # skip the very first (cold) frame
                times.append(dt)
                for k, v in res.stage_ms.items():
                    stages.setdefault(k, []).append(v)
    return {'full_pipeline_ms': _stats(times), 'full_sequence': sequence,
            'full_stages_ms': {k: round(float(np.median(v)), 3) for k, v in stages.items()}}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--json', metavar='FILE', help='write the results as JSON here')
    parser.add_argument('--repeats', type=int, default=200, help='single-frame repetitions')
    parser.add_argument('--flow', action='store_true', help='also time optical-flow methods')
    parser.add_argument('--process', action='store_true',
                        help='also measure offline bag throughput (frames/s, 1 and N jobs)')
    parser.add_argument('--ros', action='store_true',
                        help='also measure end-to-end latency over DDS against a relay node')
    parser.add_argument('--no-pin', action='store_true', help='do not pin to one CPU core')
    parser.add_argument('--params', metavar='YAML',
                        help='parameter file (e.g. config/endeff_fast.yaml); default: defaults')


def run(args: argparse.Namespace) -> int:
    cpu = None if args.no_pin else _pin_one_core()
    out: dict[str, Any] = {'machine': {'python': platform.python_version(),
                                       'cpu_count': os.cpu_count(), 'pinned_cpu': cpu}}
    params = load_params_option(args.params, 'python -m tools.bench')
    if params is not None:
        out['params'] = args.params
    out.update(bench_single_frame(repeats=args.repeats, params=params))
    out.update(bench_full_pipeline(params=params))
    if args.flow:
        from tools.flow_eval import flow_benchmark

        out['flow'] = flow_benchmark()
    if args.process:
        from tools.bench_process import bench_process, whole_command

        with _all_cores():  # N bags on N processes: the one-core pin must not be inherited
            out['process'] = bench_process()
        whole = whole_command(cpu=cpu)
        # What the full pipeline's median allows, and the share of it the command reaches.
        whole['ratio_to_full_pipeline'] = round(
            whole['fps'] * out['full_pipeline_ms']['median'] / 1000.0, 3)
        out['process']['whole_command'] = whole
    if args.ros:
        from tools.latency_bench import benchmark as ros_benchmark

        out['ros'] = ros_benchmark(node_params=params.to_dict() if params else None)
    print_json(out, args.json)
    return 0


if __name__ == '__main__':
    parser = argparse.ArgumentParser(prog='python -m tools.bench')
    add_arguments(parser)
    sys.exit(run(parser.parse_args()))
