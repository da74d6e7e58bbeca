"""One replay run over DDS, every participant in its own process.

``run_over_dds(bag)`` starts ``endeff_node`` (and optionally the relay) and a driver process that
replays the bag (:mod:`tools.replay`) and collects the outputs, all with the same
environment (Fast DDS, the SHM profile unless ``profile=False``, a private ROS domain). The
driver writes a JSON record; ``run_over_dds`` returns it as a dict::

    {'bag', 'frame_id', 'depth_sent': [stamp, ...], 'waited_out', 'replay_seconds',
     'drop_color_every', 'no_color', 'color_sent': [stamp, ...], 'color_dropped': [...],
     'depth_color_dropped': [depth stamp whose colour was withheld, ...],
     'unpaired_depth': [depth stamp the bag itself has no colour for, ...],
     'outputs': {'node': {stamp: {'frame_id', 'latency_ms', 'x', 'y', 'z', 'id', 'state'}},
                 'relay': {...}},
     'duplicates': {'node': 0, ...}, 'markers': {stamp: [[id, x, y, z], ...]},
     'latency': {'node': {...}, 'relay': {...}}, 'diagnostics': {key: value}}

Stamps are integers (nanoseconds). The driver is ``python -m tools.dds_run``.
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
from typing import Any

from endeff_ros.ros.processing import NODE_PARAMS
from tools.procs import ros_env, start, stop


def _node_args(namespace: str, params: dict[str, Any]) -> list[str]:
    args = ['--ros-args', '-r', f'__ns:={namespace}']
    for key, value in params.items():
        text = str(value).lower() if isinstance(value, bool) else str(value)
        args += ['-p', f'{key}:={text}']
    return args


_DEFAULT_SLOP_S = next(r['default'] for r in NODE_PARAMS if r['name'] == 'sync_slop')


def run_over_dds(bag: str | Path, *, rate_hz: float | None = None, relay: bool = False,
                markers: bool = True,
                profile: bool = True, node_params: dict[str, Any] | None = None,
                namespace: str = '/camera', domain_id: int | None = None,
                max_frames: int | None = None, loops: int = 1, jitter_s: float = 0.008,
                frame_timeout_s: float = 20.0, timeout_s: float = 1800.0,
                drop_color_every: int | None = None, no_color: bool = False) -> dict[str, Any]:
    """Replay ``bag`` to a fresh ``endeff_node`` process and return the collected record.

    ``rate_hz=None`` replays in lock-step (every frame processed); otherwise at that rate.
    ``loops`` replays the bag that many times (re-stamped, see :meth:`BagSource.looped`).
    ``markers=False``: nobody subscribes to ``end_effectors/markers`` (the node then does not
    build them), as for a consumer of ``end_effectors`` alone.
    ``drop_color_every=N`` withholds every N-th colour image, ``no_color`` all of them (the
    colour topic is then not advertised); the record names the depth images concerned.
    Every child process is stopped (SIGINT, then harder) before returning.
    """
    if domain_id is None:
        domain_id = 100 + os.getpid() % 100
    env = ros_env(profile=profile, domain_id=domain_id)
    with tempfile.TemporaryDirectory(prefix='endeff_dds_run_') as tmp:
        out = Path(tmp) / 'record.json'
        logs = {name: open(Path(tmp) / f'{name}.log', 'w+', encoding='utf-8')  # noqa: SIM115
                for name in ('node', 'relay', 'driver')}
        procs: list[subprocess.Popen] = []
        try:
            procs.append(start(['-m', 'endeff_ros.ros.node',
                                *_node_args(namespace, node_params or {})], env,
                               stdout=logs['node'], stderr=subprocess.STDOUT))
            if relay:
                procs.append(start(['-m', 'tools.relay',
                                    *_node_args(namespace, {})], env,
                                   stdout=logs['relay'], stderr=subprocess.STDOUT))
            driver = ['-m', 'tools.dds_run', '--bag', str(bag), '--out', str(out),
                      '--namespace', namespace, '--jitter', str(jitter_s),
                      '--frame-timeout', str(frame_timeout_s),
                      '--sync-slop', str((node_params or {}).get('sync_slop', _DEFAULT_SLOP_S))]
            if rate_hz is not None:
                driver += ['--rate', str(rate_hz)]
            if relay:
                driver += ['--relay']
            if not markers:
                driver += ['--no-markers']
            if max_frames is not None:
                driver += ['--max-frames', str(max_frames)]
            if loops > 1:
                driver += ['--loops', str(loops)]
            if drop_color_every is not None:
                driver += ['--drop-color-every', str(drop_color_every)]
            if no_color:
                driver += ['--no-color']
            proc = start(driver, env, stdout=logs['driver'], stderr=subprocess.STDOUT)
            procs.append(proc)
            try:
                proc.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                pass
        finally:
            for p in reversed(procs):
                stop(p)
        text = {}
        for name, fh in logs.items():
            fh.seek(0)
            text[name] = fh.read()[-4000:]
            fh.close()
        if not out.is_file():
            msg = (f'replay run for {bag} produced no record.\n--- driver log ---\n'
                   f'{text["driver"]}\n--- node log ---\n{text["node"]}')
            raise RuntimeError(msg)
        record = json.loads(out.read_text(encoding='utf-8'))
    record['logs'] = text
    for key in ('outputs', 'markers'):
        record[key] = _int_keys(record.get(key, {}))
    return record


def _int_keys(d: dict[str, Any]) -> dict[Any, Any]:
    out: dict[Any, Any] = {}
    for k, v in d.items():
        key = int(k) if k.lstrip('-').isdigit() else k
        out[key] = _int_keys(v) if isinstance(v, dict) and key == k else v
    return out


# -------------------------------------------------------------------------------- driver
def _driver(args: argparse.Namespace) -> int:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor

    from tools.replay import (
        KINDS,
        BagSource,
        Collector,
        Replayer,
        color_dropped_depth,
        latency_summary,
        replay,
        spin_for,
        spin_until,
        unpaired_depth,
    )

    rclpy.init()
    node = rclpy.create_node('endeff_replay')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    ns = args.namespace.rstrip('/')
    topics = {'node': f'{ns}/end_effectors'}
    if args.relay:
        topics['relay'] = f'{ns}/relay/end_effectors'
    diagnostics: dict[str, str] = {}

    def on_diag(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if 'endeff_node' in status.name:
                diagnostics.clear()
                diagnostics.update({v.key: v.value for v in status.values})

    node.create_subscription(DiagnosticArray, '/diagnostics', on_diag, 10)
    record: dict[str, Any] = {'bag': str(args.bag)}
    with BagSource(args.bag) as source:
        replayer = Replayer(node, ns, tuple(k for k in KINDS
                                            if not (args.no_color and k == 'color')))
        collector = Collector(node, topics, markers_topic=None if args.no_markers
                              else f'{ns}/end_effectors/markers')
        if not spin_until(executor, lambda: replayer.matched(1 + args.relay) and
                          collector.matched(), 90.0):
            print('endeff_node (or the relay) never appeared on DDS', file=sys.stderr)
            return 1
        spin_for(executor, 0.5)
        stats = replay(executor, source, replayer, collector=collector, rate_hz=args.rate,
                       jitter_s=args.jitter, frame_timeout_s=args.frame_timeout,
                       max_frames=args.max_frames, loops=args.loops,
                       drop_color_every=args.drop_color_every, no_color=args.no_color)
        sent = stats.depth_sent
        spin_until(executor, lambda: all(s in collector.clouds[n] for n in topics
                                         for s in sent), 5.0 if args.rate else 30.0)
        spin_until(executor, lambda: all(s in collector.markers for s in sent
                                         if s in collector.clouds['node']), 2.0)
        if args.rate:
            spin_for(executor, 1.2)  # a last diagnostics message (node period 1 s)
        record.update(depth_sent=sent, waited_out=stats.waited_out,
                      replay_seconds=stats.seconds, duplicates=collector.duplicates,
                      diagnostics=diagnostics)
        record['outputs'] = {name: {str(s): {
            'frame_id': o.frame_id, 'latency_ms': (o.receipt_ns - replayer.sent[s]) / 1e6
            if s in replayer.sent else None,
            **{f: o.points[f].tolist() for f in ('x', 'y', 'z', 'id', 'state')
               if f in (o.points.dtype.names or ())}}
            for s, o in clouds.items()} for name, clouds in collector.clouds.items()}
        slop_ns = round(args.sync_slop * 1e9)
        # Unpaired: no colour in the bag itself; colour dropped: withheld by this replay.
        unpaired = unpaired_depth(sent, [*stats.color_sent, *stats.color_dropped], slop_ns)
        lost = color_dropped_depth(sent, stats.color_sent, stats.color_dropped, slop_ns)
        record.update(drop_color_every=args.drop_color_every, no_color=args.no_color,
                      color_sent=stats.color_sent, color_dropped=stats.color_dropped,
                      depth_color_dropped=sorted(lost), unpaired_depth=sorted(unpaired))
        record['latency'] = {name: latency_summary(
            replayer.sent, collector.clouds[name], sent,
            *((unpaired, lost) if name == 'node' else ()))
            for name in topics}
        record['markers'] = {str(s): [[m.id, m.pose.position.x, m.pose.position.y,
                                       m.pose.position.z] for m in arr.markers
                                      if m.ns == 'end_effectors' and m.action == 0]
                             for s, arr in collector.markers.items()}
    Path(args.out).write_text(json.dumps(record), encoding='utf-8')
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def main(argv: list[str] | None = None) -> int:
    from tools.replay import positive_int

    parser = argparse.ArgumentParser(description='Replay driver of run_over_dds (internal).')
    parser.add_argument('--bag', required=True)
    parser.add_argument('--out', required=True)
    parser.add_argument('--namespace', default='/camera')
    parser.add_argument('--rate', type=float, default=None)
    parser.add_argument('--relay', action='store_true')
    parser.add_argument('--no-markers', action='store_true',
                        help='do not subscribe to the markers (the node then skips them)')
    parser.add_argument('--jitter', type=float, default=0.008)
    parser.add_argument('--frame-timeout', type=float, default=20.0)
    parser.add_argument('--max-frames', type=int, default=None)
    parser.add_argument('--loops', type=int, default=1)
    parser.add_argument('--drop-color-every', type=positive_int, default=None, metavar='N',
                        help='withhold every N-th colour image')
    parser.add_argument('--no-color', action='store_true',
                        help='send no colour image (the colour topic is not advertised)')
    parser.add_argument('--sync-slop', type=float, default=_DEFAULT_SLOP_S,
                        help="the node's sync_slop: depth images without colour this close "
                             'are unpaired inputs, not drops')
    args = parser.parse_args(argv)
    t0 = time.monotonic()
    try:
        return _driver(args)
    except KeyboardInterrupt:
        return 130
    finally:
        print(f'driver finished after {time.monotonic() - t0:.1f} s', file=sys.stderr)


if __name__ == '__main__':
    sys.exit(main())
