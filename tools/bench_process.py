"""Throughput of ``endeff process``: frames/s on one core, and N bags on N processes.

:func:`bench_process` writes 640x480 input bags (frames of the synthetic ``jumping_jacks``
sequence when :mod:`endeff_ros.synth` is available, else a plain moving-boxes scene), then times
:func:`endeff_ros.bag.process.process_bags` in fresh interpreters:

- ``one_core``: one bag, one process pinned to one CPU, BLAS/OpenMP/OpenCV limited to one thread;
- ``n_processes``: N copies of the bag with ``jobs=N`` (what ``endeff process --jobs N`` does),
  the worker processes limited to N CPUs and one thread each.

Times include reading, synchronising, tracking, building and writing the output messages (the
whole command), but not interpreter start-up. Prints/returns JSON; nothing is asserted.

``python -m tools.bench_process [--frames 30] [--bags 2] [--json FILE]``
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from endeff_ros.cli_common import print_json

if TYPE_CHECKING:
    from collections.abc import Iterator

    import numpy.typing as npt

THREAD_VARS = ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS',
               'NUMEXPR_NUM_THREADS', 'VECLIB_MAXIMUM_THREADS')
PERIOD_NS = 33_333_333
START_NS = 1_700_000_000 * 10**9


def _boxes_frames(n: int, width: int = 640, height: int = 480
                  ) -> Iterator[tuple[int, npt.NDArray[np.uint8], npt.NDArray[np.float32]]]:
    """Fallback scene: a torso with four moving limbs (boxes) at 2.5 m before a far wall."""
    for i in range(n):
        depth = np.full((height, width), 6.0, np.float32)
        cx, cy = width // 2, height // 2
        depth[cy - 90:cy + 60, cx - 40:cx + 40] = 2.5
        swing = int(60 * np.sin(0.3 * i))
        depth[cy - 80 + swing:cy - 60 + swing, cx - 160:cx - 40] = 2.45
        depth[cy - 80 - swing:cy - 60 - swing, cx + 40:cx + 160] = 2.45
        depth[cy + 60:cy + 200, cx - 35:cx - 15] = 2.5
        depth[cy + 60:cy + 200, cx + 15:cx + 35] = 2.5
        depth[cy - 130:cy - 90, cx - 20:cx + 20] = 2.5
        color = np.where(depth[..., None] < 3.0, np.uint8(180), np.uint8(60)).repeat(3, 2)
        yield START_NS + i * PERIOD_NS, color.astype(np.uint8), depth


def _looped(frames: list[tuple[int, Any, Any]], n: int) -> list[tuple[int, Any, Any]]:
    """``frames`` repeated (stamps continuing at the same period) up to ``n`` frames."""
    period = frames[1][0] - frames[0][0] if len(frames) > 1 else 33_333_334
    return [(frames[0][0] + k * period, *frames[k % len(frames)][1:]) for k in range(n)]


def _source_frames(n: int) -> tuple[str, list[tuple[int, Any, Any]], Any]:
    """(description, [(stamp, colour RGB, depth m)], intrinsics) of ``n`` 640x480 frames (the
    synthetic sequence is looped when ``n`` is longer)."""
    from endeff_ros.core.types import KINECT_640

    try:
        from endeff_ros.synth import render_sequence

        frames = []
        intr = None
        for f in render_sequence('jumping_jacks'):
            if len(frames) >= n:
                break
            if f.color is None or f.depth is None:
                continue
            frames.append((f.stamp_ns, f.color, f.depth))
            intr = f.intrinsics
        if len(frames) >= min(n, 10) and intr is not None:
            return f'synth jumping_jacks ({len(frames)} frames, looped)', _looped(frames, n), intr
    except ImportError:
        pass
    intr = KINECT_640
    return 'moving boxes', list(_boxes_frames(n)), intr


def write_input_bag(path: Path, frames: list[tuple[int, Any, Any]], intr: Any,
                    storage: str = 'mcap') -> None:
    """Write colour (rgb8), depth (16UC1) and camera info in the benchmark-bag form."""
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import StoragePlugin
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    t = ts.types
    frame_id = 'camera_color_optical_frame'

    def header(stamp: int) -> Any:
        sec, nsec = divmod(stamp, 10**9)
        return t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](
            sec=sec, nanosec=nsec), frame_id=frame_id)

    def image(stamp: int, arr: npt.NDArray[Any], enc: str) -> Any:
        arr = np.ascontiguousarray(arr)
        return t['sensor_msgs/msg/Image'](header=header(stamp), height=arr.shape[0],
                                          width=arr.shape[1], encoding=enc, is_bigendian=0,
                                          step=arr.nbytes // arr.shape[0],
                                          data=arr.view(np.uint8).reshape(-1))

    k = np.array([intr.fx, 0, intr.cx, 0, intr.fy, intr.cy, 0, 0, 1], np.float64)
    p = np.array([intr.fx, 0, intr.cx, 0, 0, intr.fy, intr.cy, 0, 0, 0, 1, 0], np.float64)
    roi = t['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0, width=0,
                                                do_rectify=False)
    plugin = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}[storage]
    with Writer(path, version=9, storage_plugin=plugin) as w:
        c_col = w.add_connection('/camera/color/image_raw', 'sensor_msgs/msg/Image', typestore=ts)
        c_dep = w.add_connection('/camera/depth/image_raw', 'sensor_msgs/msg/Image', typestore=ts)
        c_inf = w.add_connection('/camera/depth/camera_info', 'sensor_msgs/msg/CameraInfo',
                                 typestore=ts)
        for stamp, color, depth in frames:
            mm = np.where(np.isfinite(depth), np.round(depth * 1000.0), 0).astype('<u2')
            info = t['sensor_msgs/msg/CameraInfo'](
                header=header(stamp), height=intr.height, width=intr.width,
                distortion_model='plumb_bob', d=np.zeros(5), k=k, r=np.eye(3).reshape(-1), p=p,
                binning_x=0, binning_y=0, roi=roi)
            w.write(c_inf, stamp, ts.serialize_cdr(info, 'sensor_msgs/msg/CameraInfo'))
            w.write(c_dep, stamp + 1, ts.serialize_cdr(image(stamp, mm, '16UC1'),
                                                       'sensor_msgs/msg/Image'))
            w.write(c_col, stamp + 2, ts.serialize_cdr(image(stamp + 2_000_000, color, 'rgb8'),
                                                       'sensor_msgs/msg/Image'))


def measure(inputs: list[str], output: str, jobs: int, cpus: list[int] | None = None
            ) -> dict[str, Any]:
    """Time one ``process_bags`` run in this process (call it in a fresh interpreter)."""
    if cpus and hasattr(os, 'sched_setaffinity'):
        os.sched_setaffinity(0, set(cpus))
    try:
        import cv2

        cv2.setNumThreads(1)
    except ImportError:  # pragma: no cover - OpenCV is a dependency of the core
        pass
    import endeff_ros.core.tracker  # noqa: F401 - imports (OpenCV, scipy) are not timed
    from endeff_ros.bag.process import process_bags
    from endeff_ros.ros import convert

    convert.make_header(0, '')  # imports the rclpy message modules before timing
    t0 = time.perf_counter()
    results = process_bags(inputs, output, jobs=jobs, show_progress=False)
    seconds = time.perf_counter() - t0
    errors = [r.error for r in results if r.error]
    frames = sum(r.frames for r in results)
    return {'bags': len(inputs), 'jobs': jobs, 'frames': frames, 'seconds': round(seconds, 3),
            'fps': round(frames / seconds, 2) if seconds > 0 else 0.0,
            'per_bag_fps': [round(r.fps, 2) for r in results], 'errors': errors}


def _run_child(inputs: list[Path], output: Path, jobs: int, cpus: list[int]) -> dict[str, Any]:
    env = dict(os.environ)
    env.update({k: '1' for k in THREAD_VARS})
    code = ('import json, sys\n'
            'from tools.bench_process import measure\n'
            'a = json.loads(sys.argv[1])\n'
            'print(json.dumps(measure(a["inputs"], a["output"], a["jobs"], a["cpus"])))\n')
    arg = json.dumps({'inputs': [str(p) for p in inputs], 'output': str(output), 'jobs': jobs,
                      'cpus': cpus})
    out = subprocess.run([sys.executable, '-c', code, arg], env=env, check=True,
                         capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def whole_command(*, frames: int = 300, repeats: int = 3, cpu: int | None = None,
                  storage: str = 'mcap', workdir: str | Path | None = None) -> dict[str, Any]:
    """Wall time of the whole ``endeff process`` command (interpreter start, imports, reading,
    tracking, writing) on one ``frames``-frame bag, pinned to one CPU; median of ``repeats``."""
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else [0]
    cpu = cpus[-1] if cpu is None else cpu
    env = dict(os.environ)
    env.update({k: '1' for k in THREAD_VARS})
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        root = Path(tmp)
        source, data, intr = _source_frames(frames)
        write_input_bag(root / 'in', data, intr, storage)
        seconds = []
        for k in range(repeats):
            cmd = [sys.executable, '-m', 'endeff_ros.cli', 'process', str(root / 'in'), '-o',
                   str(root / f'out{k}')]
            t0 = time.perf_counter()
            subprocess.run(cmd, env=env, check=True, capture_output=True,
                           preexec_fn=lambda: os.sched_setaffinity(0, {cpu}))
            seconds.append(time.perf_counter() - t0)
    median = float(np.median(seconds))
    return {'source': source, 'frames': len(data), 'cpu': cpu,
            'seconds': [round(s, 3) for s in seconds], 'median_s': round(median, 3),
            'fps': round(len(data) / median, 2)}


def bench_process(*, frames: int = 30, bags: int = 2, storage: str = 'mcap',
                  workdir: str | Path | None = None) -> dict[str, Any]:
    """Frames/s of ``endeff process`` on one core and with ``bags`` bags on as many processes."""
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else list(
        range(os.cpu_count() or 1))
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        root = Path(tmp)
        source, data, intr = _source_frames(frames)
        inputs = []
        for b in range(bags):
            inputs.append(root / 'in' / f'bag{b}')
            write_input_bag(inputs[-1], data, intr, storage)
        one = _run_child(inputs[:1], root / 'out1', 1, cpus[:1])
        many = _run_child(inputs, root / 'outN', bags, cpus[:bags])
    speedup = many['fps'] / one['fps'] if one['fps'] else 0.0
    return {
        'bench': 'endeff process throughput',
        'source': source, 'width': intr.width, 'height': intr.height, 'storage': storage,
        'frames_per_bag': len(data), 'cpus_available': len(cpus),
        'one_core': one,
        'n_processes': many,
        'speedup': round(speedup, 2),
        'parallel_efficiency': round(speedup / bags, 2) if bags else 0.0,
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the benchmark."""
    parser.add_argument('--frames', type=int, default=30, help='frames per bag (default 30)')
    parser.add_argument('--bags', type=int, default=2,
                        help='bags (= processes) for the parallel run (default 2)')
    parser.add_argument('--storage', choices=('mcap', 'sqlite3'), default='mcap')
    parser.add_argument('--json', metavar='FILE', help='also write the JSON here')


def run(args: argparse.Namespace) -> int:
    """Run :func:`bench_process` and print its JSON."""
    result = bench_process(frames=args.frames, bags=args.bags, storage=args.storage)
    print_json(result, args.json)
    return 0 if not (result['one_core']['errors'] or result['n_processes']['errors']) else 1


def main(argv: list[str] | None = None) -> int:
    """``python -m tools.bench_process``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == '__main__':
    sys.exit(main())
