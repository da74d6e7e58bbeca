"""Replay, DDS-run and DDS-profile helpers that need no running DDS."""

from __future__ import annotations

import argparse
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from endeff_ros.ros import convert
from tools.procs import profile_path, ros_env
from tools.replay import (
    Output,
    RawMessage,
    ReplayStats,
    cdr_stamp,
    color_dropped_depth,
    jittered,
    latency_summary,
    positive_int,
    replay,
    restamp,
    unpaired_depth,
)

NS = '{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}'


def _raw(stamp_ns: int) -> bytes:
    img = convert.array_to_image_msg(convert.make_header(stamp_ns, 'f'),
                                     np.zeros((2, 2, 3), np.uint8))
    return convert.serialize(img)


def test_cdr_stamp_and_restamp():
    raw = _raw(1_700_000_001_250_000_000)
    assert cdr_stamp(raw) == 1_700_000_001_250_000_000
    moved = restamp(raw, 1_700_000_009_000_000_007)
    assert cdr_stamp(moved) == 1_700_000_009_000_000_007 and len(moved) == len(raw)
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import Image

    msg = deserialize_message(moved, Image)
    assert convert.stamp_to_ns(msg.header.stamp) == 1_700_000_009_000_000_007
    assert msg.encoding == 'rgb8' and msg.header.frame_id == 'f'


def test_jitter_reorders_within_bounds_only():
    period = 33_000_000
    msgs = [RawMessage(kind, i * period + off, b'')
            for i in range(200) for kind, off in (('camera_info', 0), ('color', 2_000_000),
                                                   ('depth', 0))]
    out = list(jittered(iter(msgs), 0.008, seed=1))
    assert sorted(m.stamp_ns for _, m in out) == sorted(m.stamp_ns for m in msgs)
    keys = [k for k, _ in out]
    assert keys == sorted(keys)
    assert all(0 <= k - m.stamp_ns <= 8_000_000 for k, m in out)
    # colour and depth of a frame swap order sometimes, frames never mix
    order = [(m.stamp_ns // period, m.kind) for _, m in out if m.kind != 'camera_info']
    swapped = sum(order[j][1] == 'color' and order[j + 1][1] == 'depth'
                  for j in range(len(order) - 1) if order[j][0] == order[j + 1][0])
    assert 0 < swapped < 200
    assert [f for f, _ in order] == sorted(f for f, _ in order)


def test_latency_summary_counts_drops():
    sent = {s: 1_000_000 * s for s in range(1, 11)}
    outputs = {s: Output(sent[s] + 5_000_000 * s, 'f', np.zeros(0)) for s in range(1, 9)}
    out = latency_summary(sent, outputs, sorted(sent))
    assert out['frames_sent'] == 10 and out['outputs'] == 8 and out['dropped_frames'] == 2
    assert out['latency_ms_max'] == 40.0 and 20.0 <= out['latency_ms_p50'] <= 25.0
    assert out['unpaired_inputs'] == 0


def test_frames_without_a_colour_partner_are_unpaired_not_dropped():
    depth = [1_000, 2_000, 3_000, 4_000, 5_000]
    color = [1_004, 2_010, 4_003, 5_002]  # none near 3_000; 2_010 is outside a 5 ns slop
    assert unpaired_depth(depth, color, 5) == {2_000, 3_000}
    assert unpaired_depth(depth, color, 10) == {3_000}
    assert unpaired_depth(depth, [], 10) == set(depth)
    sent = {s: s for s in depth}
    outputs = {s: Output(s + 1_000_000, 'f', np.zeros(0)) for s in (1_000, 5_000)}
    out = latency_summary(sent, outputs, depth, unpaired_depth(depth, color, 10))
    assert out['outputs'] == 2 and out['unpaired_inputs'] == 1 and out['dropped_frames'] == 2


def test_fastdds_profile_is_a_32mb_shm_plus_udp_default_profile():
    root = ET.parse(profile_path()).getroot()
    transports = {t.findtext(f'{NS}transport_id'): t
                  for t in root.iter(f'{NS}transport_descriptor')}
    kinds = {t.findtext(f'{NS}type'): t for t in transports.values()}
    assert set(kinds) == {'SHM', 'UDPv4'}
    assert int(kinds['SHM'].findtext(f'{NS}segment_size')) == 32 * 1024 * 1024
    participant = root.find(f'{NS}participant')
    assert participant.get('is_default_profile') == 'true'
    rtps = participant.find(f'{NS}rtps')
    assert rtps.findtext(f'{NS}useBuiltinTransports') == 'false'
    used = [t.text for t in rtps.find(f'{NS}userTransports')]
    assert set(used) == set(transports)


def test_ros_env_sets_or_removes_the_profile():
    base = {'PATH': '/bin', 'FASTRTPS_DEFAULT_PROFILES_FILE': '/elsewhere.xml'}
    on = ros_env(profile=True, domain_id=42, base=base)
    assert Path(on['FASTDDS_DEFAULT_PROFILES_FILE']) == profile_path()
    assert on['FASTRTPS_DEFAULT_PROFILES_FILE'] == on['FASTDDS_DEFAULT_PROFILES_FILE']
    assert on['ROS_DOMAIN_ID'] == '42' and on['RMW_IMPLEMENTATION'] == 'rmw_fastrtps_cpp'
    off = ros_env(profile=False, base=base)
    assert 'FASTDDS_DEFAULT_PROFILES_FILE' not in off
    assert 'FASTRTPS_DEFAULT_PROFILES_FILE' not in off


class _Source:
    """A bag stand-in for :func:`replay`: ``frames`` frames of camera info, colour (2 ms
    late) and depth, at 30 Hz."""

    def __init__(self, frames: int) -> None:
        period = 33_333_333
        kinds = (('camera_info', 0), ('color', 2_000_000), ('depth', 0))
        self.msgs = [RawMessage(kind, 10**18 + i * period + off, b'')
                     for i in range(frames) for kind, off in kinds]

    def depth_stamps(self) -> list[int]:
        return [m.stamp_ns for m in self.msgs if m.kind == 'depth']

    def looped(self, loops: int):
        assert loops == 1
        return iter(self.msgs)


class _Publisher:
    def __init__(self) -> None:
        self.sent: list[RawMessage] = []

    def publish(self, msg: RawMessage) -> None:
        self.sent.append(msg)


class _Executor:
    def spin_once(self, timeout_sec: float = 0.0) -> None:
        pass


def _replay(frames: int, **kw) -> tuple[_Source, _Publisher, ReplayStats]:
    source, pub = _Source(frames), _Publisher()
    return source, pub, replay(_Executor(), source, pub, jitter_s=0.0, **kw)


def test_every_nth_colour_image_is_withheld_and_its_depth_frame_named():
    source, pub, stats = _replay(25, drop_color_every=10)
    colors = [m.stamp_ns for m in source.msgs if m.kind == 'color']
    depth = source.depth_stamps()
    assert stats.color_dropped == [colors[9], colors[19]]
    assert [m.stamp_ns for m in pub.sent if m.kind == 'color'] == stats.color_sent
    assert sorted(stats.color_sent + stats.color_dropped) == colors
    assert stats.depth_sent == depth  # depth and camera info untouched
    assert sum(m.kind == 'camera_info' for m in pub.sent) == 25
    slop = 15_000_000
    assert color_dropped_depth(depth, stats.color_sent, stats.color_dropped, slop) == {
        depth[9], depth[19]}


def test_no_colour_withholds_every_colour_image():
    source, pub, stats = _replay(6, no_color=True)
    assert not any(m.kind == 'color' for m in pub.sent) and stats.color_sent == []
    assert len(stats.color_dropped) == 6 and len(stats.depth_sent) == 6
    depth = source.depth_stamps()
    assert color_dropped_depth(depth, [], stats.color_dropped, 15_000_000) == set(depth)


def test_a_depth_frame_the_bag_left_unpaired_is_not_counted_as_withheld():
    depth = [1_000, 2_000, 3_000, 4_000]
    sent, dropped = [1_001, 4_002], [2_003]  # the bag has no colour near 3_000
    assert color_dropped_depth(depth, sent, dropped, 10) == {2_000}
    assert unpaired_depth(depth, sent + dropped, 10) == {3_000}


def test_a_bad_drop_period_is_refused():
    assert positive_int('10') == 10
    for text in ('0', '-3', 'x', '2.5'):
        with pytest.raises(argparse.ArgumentTypeError, match='at least 1'):
            positive_int(text)
    with pytest.raises(ValueError, match='drop_color_every'):
        _replay(3, drop_color_every=0)


def test_latency_summary_accounts_for_withheld_colour_apart():
    stamps = list(range(1, 11))
    sent = {s: 0 for s in stamps}
    outputs = {s: Output(s * 1_000_000, 'f', np.zeros(0)) for s in stamps if s not in (2, 5, 9)}
    out = latency_summary(sent, outputs, stamps, unpaired={9}, color_dropped={4, 5, 6})
    assert out['frames_sent'] == 10 and out['outputs'] == 7
    assert out['dropped_frames'] == 1 and out['unpaired_inputs'] == 1  # 2 and 9
    lost = out['color_dropped']
    assert lost['frames_sent'] == 3 and lost['outputs'] == 2 and lost['dropped_frames'] == 1
    assert lost['latency_ms_max'] == 6.0 and lost['latency_ms_p50'] == 5.0
    assert out['latency_ms_max'] == 10.0  # every output, withheld colour or not
    none = latency_summary(sent, outputs, stamps)
    assert none['color_dropped'] == {'frames_sent': 0, 'outputs': 0, 'dropped_frames': 0}
    assert none['dropped_frames'] == 3


def test_compare_drops_runs_the_three_cases_in_turn(monkeypatch):
    import tools.latency_bench as bench

    calls = []

    def fake(bag, **kw):
        calls.append(kw)
        n = len(calls)
        lost = {'frames_sent': 1, 'outputs': 1, 'dropped_frames': 0, 'latency_ms_p50': 40.0,
                'latency_ms_p95': 40.0}
        node = {'frames_sent': 10, 'outputs': 10, 'dropped_frames': 0, 'unpaired_inputs': 0,
                'latency_ms_p50': 10.0 + n, 'latency_ms_p95': 20.0 + 2 * n, 'color_dropped': lost}
        return {'color': str(n), 'node': node, 'relay': {'latency_ms_p95': 5.0}}

    monkeypatch.setattr(bench, 'ros_latency_bench', fake)
    result = bench.compare_drops('bag', rounds=2, rate_hz=30.0, loops=1)
    assert [(c.get('drop_color_every'), c.get('no_color', False)) for c in calls] == [
        (None, False), (10, False), (None, True)] * 2
    assert all(c['rate_hz'] == 30.0 and c['loops'] == 1 for c in calls)
    cases = result['cases']
    # medians over the two rounds: all colour runs 1 and 4, 1 in 10 runs 2 and 5, none 3 and 6
    assert cases['all_color']['node']['latency_ms_p50'] == 12.5
    assert cases['no_color']['node']['latency_ms_p95'] == 29.0
    assert cases['drop_color_1_in_10']['node']['outputs'] == 20
    assert cases['drop_color_1_in_10']['node']['color_dropped']['frames_sent'] == 2
    assert result['differences'] == {'drop_color_1_in_10': {'p50_ms': 1.0, 'p95_ms': 2.0},
                                     'no_color': {'p50_ms': 2.0, 'p95_ms': 4.0}}
    assert result['targets']['drop_color_1_in_10'] == {
        'percentile': 'p95', 'limit_ms': 5.0, 'met': True, 'every_frame_answered': True}
    assert result['targets']['no_color']['met'] is True  # 2 ms over, 10 allowed
    monkeypatch.setattr(bench, 'DROP_TARGETS', {'no_color': ('p50', 1.5)})
    assert bench.compare_drops('bag', rounds=2)['targets']['no_color']['met'] is False


def test_command_line_prints_usage_and_refuses_a_missing_bag(tmp_path: Path) -> None:
    """``python -m tools.replay --help`` prints its usage (it printed nothing: the module had
    no entry point); a bag that is not there is one line and status 2, before any DDS."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    done = subprocess.run([sys.executable, '-m', 'tools.replay', '--help'], cwd=root,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith('usage: python -m tools.replay') and 'BAG' in done.stdout
    assert '--rate' in done.stdout and '--namespace' in done.stdout
    missing = tmp_path / 'nowhere'
    done = subprocess.run([sys.executable, '-m', 'tools.replay', str(missing)], cwd=root,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.splitlines() == [f'tools.replay: {missing}: no such file or directory']
