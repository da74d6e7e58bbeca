"""Replay, session and DDS-profile helpers that need no running DDS."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from endeff_ros.ros import convert
from tools.procs import profile_path, ros_env
from tools.replay import (
    Output,
    RawMessage,
    cdr_stamp,
    jittered,
    latency_summary,
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
