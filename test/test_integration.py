"""End to end over DDS: a synthetic bag replayed to endeff_node in its own process.

The node runs as a subprocess with the Fast DDS SHM profile; a driver process replays the bag
(original stamps, jittered colour/depth send times, lock-step) and a subscriber node in it
collects the outputs (:func:`tools.session.run_session`). Checked: one cloud per depth
image with its stamp and frame_id, markers equal to the cloud, and recall equal (within 0.02) to
the offline evaluation of the same bag.
"""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.integration

SEQUENCE = 'punching'  # occlusions: recall well below 1, so the comparison means something


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    from endeff_ros.synth.cli import generate_one

    out = tmp_path_factory.mktemp('synth')
    generate_one(SEQUENCE, out, ['mcap'], True, 0)
    return out / 'mcap' / SEQUENCE


@pytest.fixture(scope='module')
def record(bag):
    from tools.session import run_session

    return run_session(bag, timeout_s=240.0, frame_timeout_s=20.0)


def _depth_frame_id(bag) -> str:
    from tools.replay import BagSource

    with BagSource(bag) as source:
        conns = [c for c in source.bag.reader.connections if c.topic == source.topics['depth']]
        _, _, raw = next(iter(source.bag.reader.messages(connections=conns)))
        return source.bag.reader.deserialize(raw, conns[0].msgtype).header.frame_id


def test_one_cloud_per_depth_frame_with_its_stamp_and_frame(bag, record):
    from tools.replay import BagSource

    with BagSource(bag) as source:
        stamps = source.depth_stamps()
    assert record['depth_sent'] == stamps, record['logs']['driver']
    clouds = record['outputs']['node']
    assert sorted(clouds) == stamps, record['logs']['node']
    assert record['duplicates']['node'] == 0
    frame_id = _depth_frame_id(bag)
    assert {c['frame_id'] for c in clouds.values()} == {frame_id}
    assert any(len(c['x']) for c in clouds.values()), 'the node found no end-effector at all'


def test_markers_match_cloud(record):
    clouds = record['outputs']['node']
    assert set(record['markers']) == set(clouds)
    for stamp, cloud in clouds.items():
        spheres = sorted(record['markers'][stamp])
        rows = sorted([int(i), x, y, z] for i, x, y, z in zip(cloud['id'], cloud['x'],
                                                             cloud['y'], cloud['z']))
        assert [s[0] for s in spheres] == [r[0] for r in rows]
        np.testing.assert_allclose(np.array(spheres)[:, 1:] if spheres else np.zeros((0, 3)),
                                   np.array(rows)[:, 1:] if rows else np.zeros((0, 3)),
                                   atol=1e-5)


def test_recall_equals_offline_evaluation(bag, record):
    from endeff_ros.evaluate import evaluate_bag
    from tools.demo import score_record
    from tools.replay import BagSource

    with BagSource(bag) as source:
        gt = source.ground_truth()
    scorer = score_record(record, gt)
    online = scorer.result()
    offline = evaluate_bag(bag).score('temporal')
    assert scorer.scored_frames > 0
    assert abs(online.recall - offline.recall) <= 0.02, (online, offline)
    assert abs(online.mean_error_m - offline.mean_error_m) <= 0.01, (online, offline)


def test_process_output_equals_node_output(bag, record, tmp_path):
    """``endeff process`` on the same bag gives the node's end-effectors, frame by frame."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    from endeff_ros.bag.process import process_bag
    from endeff_ros.ros import convert

    out = tmp_path / 'processed'
    process_bag(bag, out)
    offline = {}
    with AnyReader([out], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        conns = [c for c in reader.connections if c.msgtype == 'sensor_msgs/msg/PointCloud2']
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            offline[convert.stamp_to_ns(msg.header.stamp)] = convert.cloud_to_array(msg)
    online = {int(s): c for s, c in record['outputs']['node'].items()}
    assert sorted(offline) == sorted(online)
    for stamp, arr in offline.items():
        node = online[stamp]
        assert sorted(node['id']) == sorted(arr['id'].tolist()), stamp
        order_n, order_o = np.argsort(node['id']), np.argsort(arr['id'])
        for f in ('x', 'y', 'z'):
            np.testing.assert_allclose(np.asarray(node[f])[order_n], arr[f][order_o], atol=1e-5)
        assert np.asarray(node['state'])[order_n].tolist() == arr['state'][order_o].tolist()


def test_latency_bench_accounts_for_every_frame(bag):
    """The latency benchmark (node and relay over DDS, open loop): every depth image sent
    has an output, or is counted as dropped by the node, or as an unpaired input (the bag
    drops a colour image on purpose); latencies are positive; markers unsubscribed."""
    from tools.latency_bench import ros_latency_bench
    from tools.replay import BagSource, cdr_stamp, unpaired_depth

    result = ros_latency_bench(bag, rate_hz=15.0, loops=1)
    node, relay = result['node'], result['relay']
    with BagSource(bag) as source:
        stamps = {kind: sorted(cdr_stamp(raw) for _, raw in source._raw([source.topics[kind]]))
                  for kind in ('color', 'depth')}
    unpaired = unpaired_depth(stamps['depth'], stamps['color'], round(0.015e9))
    assert len(unpaired) == 1  # premise: the quick bag lacks one colour image
    assert node['frames_sent'] == relay['frames_sent'] == len(stamps['depth'])
    assert node['outputs'] + node['dropped_frames'] + node['unpaired_inputs'] == \
        node['frames_sent']
    assert node['unpaired_inputs'] <= 1 and node['outputs'] >= node['frames_sent'] - 4
    assert relay['unpaired_inputs'] == 0 and relay['outputs'] == relay['frames_sent']
    assert 0 < node['latency_ms_p50'] <= node['latency_ms_p95'] <= node['latency_ms_max']
    assert result['markers_subscribed'] is False
    assert int(result['node_diagnostics']['processed']) == node['outputs']
    # Depth images that came before their colour partner were estimated early (the colour
    # and depth send times are jittered independently, so about half of them).
    assert int(result['node_diagnostics']['prepared']) > 0
    assert int(result['node_diagnostics']['prepared_flow']) > 0  # and colour before depth
    # Colour images arriving while their depth partner was being estimated got their optical
    # flow computed in the callback, alongside.
    assert int(result['node_diagnostics']['flow_alongside']) > 0
