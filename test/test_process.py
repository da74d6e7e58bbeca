"""``endeff process``: output bags read back with rosbags and with mcap/mcap_ros2."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from bag_helpers import (
    TOPICS,
    BagSpec,
    FakeTracker,
    bench_like_spec,
    write_bag,
)

from endeff_ros.bag.errors import BagError
from endeff_ros.bag.process import OUTPUT_CLOUD, OUTPUT_MARKERS, process_bag, process_bags
from endeff_ros.bag.reader import read_frames
from endeff_ros.cli import main as cli_main
from endeff_ros.ros import convert

FRAME_ID = 'camera_color_optical_frame'


def _rosbags_messages(path: Path) -> list[tuple[str, str, int, Any]]:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    out = []
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as r:
        for conn, log, raw in r.messages():
            out.append((conn.topic, conn.msgtype, log, r.deserialize(raw, conn.msgtype)))
    return out


def _mcap_messages(path: Path) -> list[tuple[str, str, int, Any]]:
    from mcap_ros2.reader import read_ros2_messages

    files = list(path.glob('*.mcap')) if path.is_dir() else [path]
    assert len(files) == 1
    return [(m.channel.topic, m.schema.name, m.log_time_ns, m.ros_msg)
            for m in read_ros2_messages(str(files[0]))]


def _check_outputs(msgs: list[tuple[str, str, int, Any]], stamps: list[int],
                   expect: dict[int, np.ndarray] | None = None, markers: bool = True) -> None:
    clouds = [(log, m) for t, typ, log, m in msgs if t == OUTPUT_CLOUD]
    marker_msgs = [(log, m) for t, typ, log, m in msgs if t == OUTPUT_MARKERS]
    types = {t: typ.replace('/msg/', '/') for t, typ, _, _ in msgs}
    assert types[OUTPUT_CLOUD] == 'sensor_msgs/PointCloud2'
    assert [convert.stamp_to_ns(m.header.stamp) for _, m in clouds] == stamps
    if markers:
        assert types[OUTPUT_MARKERS] == 'visualization_msgs/MarkerArray'
        assert [convert.stamp_to_ns(m.markers[0].header.stamp) for _, m in marker_msgs] == stamps
    else:
        assert OUTPUT_MARKERS not in types
    for log, m in clouds:
        assert m.header.frame_id == FRAME_ID
        # Log time = the input depth message's log time (stamp + 7 ms in the test bags).
        assert log == convert.stamp_to_ns(m.header.stamp) + 7_000_001
        assert [f.name for f in m.fields] == list(convert.ENDEFF_DTYPE.names)
        assert m.height == 1 and m.point_step == convert.ENDEFF_DTYPE.itemsize
        pts = convert.cloud_to_array(m)
        assert len(pts) == 3
        if expect is not None:
            want = expect[convert.stamp_to_ns(m.header.stamp)]
            np.testing.assert_allclose(convert.xyz(pts), want, atol=1e-6)
            assert pts['id'].tolist() == [0, 1, 2]
    for _, m in marker_msgs:
        assert m.markers[0].action == 3  # DELETEALL
        spheres = [k for k in m.markers if k.ns == convert.NS_EFFECTOR]
        assert len(spheres) == 3 and all(k.header.frame_id == FRAME_ID for k in spheres)


def _direct(path: Path, factory: Any = FakeTracker) -> dict[int, np.ndarray]:
    """End-effectors from running the tracker directly on the bag's frames."""
    tracker = factory(None)
    out = {}
    for frame, _ in read_frames(path):
        res = tracker.update(frame)
        out[frame.stamp_ns] = np.array([t.position for t in res.tracks]).reshape(-1, 3)
    return out


@pytest.mark.parametrize(('in_storage', 'out_storage'), [('mcap', 'mcap'),
                                                         ('sqlite3', 'mcap'),
                                                         ('mcap', 'sqlite3')])
def test_output_bag_read_back(tmp_path: Path, in_storage: str, out_storage: str) -> None:
    src = tmp_path / 'in'
    truth = write_bag(src, BagSpec(frames=6, storage=in_storage, drop_color={2}))
    out = tmp_path / 'out'
    res = process_bag(src, out, storage=out_storage, markers=True, tracker_factory=FakeTracker)
    assert res.error is None and res.frames == 6
    stamps = sorted(truth)
    expect = _direct(src)
    msgs = _rosbags_messages(out)
    assert {t for t, *_ in msgs} == {OUTPUT_CLOUD, OUTPUT_MARKERS}
    _check_outputs(msgs, stamps, expect)
    if out_storage == 'mcap':
        _check_outputs(_mcap_messages(out), stamps, expect)
    # Without --markers (the default) the clouds are the same messages, and nothing else.
    plain = tmp_path / 'plain'
    process_bag(src, plain, storage=out_storage, tracker_factory=FakeTracker)
    plain_msgs = _rosbags_messages(plain)
    _check_outputs(plain_msgs, stamps, expect, markers=False)
    assert [(log, m.data.tobytes()) for t, _, log, m in plain_msgs] == [
        (log, m.data.tobytes()) for t, _, log, m in msgs if t == OUTPUT_CLOUD]
    # The colour-less frame is processed (FakeTracker marks it PREDICTED).
    states = [convert.cloud_to_array(m)['state'].tolist() for t, _, _, m in msgs
              if t == OUTPUT_CLOUD]
    assert states[2] == [1, 1, 1] and states[0] == [0, 0, 0]


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_copy_input(tmp_path: Path, storage: str) -> None:
    src = tmp_path / 'in'
    truth = write_bag(src, BagSpec(frames=5, storage=storage))
    out = tmp_path / 'out'
    process_bag(src, out, copy_input=True, markers=True, tracker_factory=FakeTracker)
    for msgs in (_rosbags_messages(out), _mcap_messages(out)):
        topics = [t for t, *_ in msgs]
        assert sorted(set(topics)) == sorted({*TOPICS.values(), OUTPUT_CLOUD, OUTPUT_MARKERS})
        assert all(topics.count(t) == 5 for t in set(topics))
        logs = [log for _, _, log, _ in msgs]
        assert logs == sorted(logs)
        _check_outputs(msgs, sorted(truth))
        depth = [m for t, _, _, m in msgs if t == TOPICS['depth']]
        assert depth[0].encoding == '16UC1' and depth[0].width == 64


def test_never_overwrites_without_force(tmp_path: Path) -> None:
    src = tmp_path / 'in'
    write_bag(src, BagSpec(frames=3))
    out = tmp_path / 'out'
    process_bag(src, out, tracker_factory=FakeTracker)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(BagError, match='exists.*--force'):
        process_bag(src, out, storage='sqlite3', tracker_factory=FakeTracker)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    res = process_bag(src, out, storage='sqlite3', force=True, tracker_factory=FakeTracker)
    assert res.frames == 3 and sorted(p.suffix for p in out.iterdir()) == ['.db3', '.yaml']
    assert not [p for p in tmp_path.iterdir() if p.name.startswith('.')]  # no leftovers
    # --force never deletes something that is not a bag, nor the input.
    other = tmp_path / 'precious'
    other.mkdir()
    (other / 'thesis.tex').write_text('x')
    with pytest.raises(BagError, match='not a bag written by endeff process'):
        process_bag(src, other, force=True, tracker_factory=FakeTracker)
    assert (other / 'thesis.tex').exists()
    with pytest.raises(BagError, match='input'):
        process_bag(src, src, force=True, tracker_factory=FakeTracker)
    assert (src / 'metadata.yaml').exists()


def test_failed_bag_leaves_no_output(tmp_path: Path) -> None:
    src = tmp_path / 'in'
    write_bag(src, BagSpec(frames=3, depth_encoding='8UC1'))
    with pytest.raises(BagError, match='8UC1'):
        process_bag(src, tmp_path / 'out', tracker_factory=FakeTracker)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['in']


def _fake_tracker_everywhere(monkeypatch: pytest.MonkeyPatch) -> None:
    import endeff_ros.core.tracker as tracker_mod

    monkeypatch.setattr(tracker_mod, 'Tracker', FakeTracker)


def test_cli_several_bags_one_bad(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    _fake_tracker_everywhere(monkeypatch)  # the serial runs; spawned workers run the real one
    ins = []
    for name, spec in [('good_a', BagSpec(frames=4)),
                       ('bad_enc', BagSpec(frames=4, depth_encoding='8UC1')),
                       ('good_b', BagSpec(frames=5, storage='sqlite3')),
                       ('no_info', BagSpec(frames=4, info_every=0))]:
        write_bag(tmp_path / 'in' / name, spec)
        ins.append(str(tmp_path / 'in' / name))
    out = tmp_path / 'out'
    status = cli_main(['process', *ins, '-o', str(out), '--jobs', '2'])
    cap = capsys.readouterr()
    assert status == 1
    assert sorted(p.name for p in out.iterdir()) == ['good_a', 'good_b']
    assert 'bad_enc: frame at stamp' in cap.err and '8UC1' in cap.err
    assert 'no_info' in cap.err and 'camera_info' in cap.err
    assert 'good_a -> ' in cap.out and '4 frames' in cap.out
    assert '\r' not in cap.err  # no progress bar when stderr is not a TTY
    n = sum(1 for t, *_ in _rosbags_messages(out / 'good_b') if t == OUTPUT_CLOUD)
    assert n == 5
    # Again: every output exists -> refused before any work (status 2), with --force ->
    # replaced (status 0).
    assert cli_main(['process', *ins[::2], '-o', str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count('use --force') == 2 and 'FAILED' not in err
    assert cli_main(['process', *ins[::2], '-o', str(out), '--force', '--storage',
                     'sqlite3']) == 0
    assert list((out / 'good_a').glob('*.db3'))


def test_same_output_names_are_an_error(tmp_path: Path) -> None:
    write_bag(tmp_path / 'a' / 'seq', BagSpec(frames=2))
    write_bag(tmp_path / 'b' / 'seq', BagSpec(frames=2))
    res = process_bags([tmp_path / 'a' / 'seq', tmp_path / 'b' / 'seq'], tmp_path / 'out',
                       tracker_factory=FakeTracker)
    assert all(r.error and 'same output' in r.error for r in res)


def test_process_equals_direct_tracker_real_core(tmp_path: Path) -> None:
    """Real Tracker: the output end-effectors equal running the Tracker on the same frames."""
    from endeff_ros.core.tracker import Tracker

    src = tmp_path / 'in'
    write_bag(src, bench_like_spec(frames=6))
    out = tmp_path / 'out'
    process_bag(src, out)
    direct = _direct(src, Tracker)
    got = {convert.stamp_to_ns(m.header.stamp): convert.xyz(convert.cloud_to_array(m))
           for t, _, _, m in _rosbags_messages(out) if t == OUTPUT_CLOUD}
    assert sorted(got) == sorted(direct)
    for stamp, want in direct.items():
        np.testing.assert_allclose(got[stamp], want, atol=1e-5)  # float32 in the cloud


def test_synth_bags_both_storages(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``endeff synth --quick`` bags (mcap and sqlite3) through ``endeff process``."""
    _fake_tracker_everywhere(monkeypatch)
    data = tmp_path / 'synth'
    assert cli_main(['synth', '--out', str(data), '--quick', '--only', 'waving_one_hand']) == 0
    ins = [data / 'mcap' / 'waving_one_hand', data / 'sqlite3' / 'waving_one_hand']
    outs = [tmp_path / 'out_mcap', tmp_path / 'out_sqlite3']
    for i, o in zip(ins, outs, strict=True):
        assert cli_main(['process', str(i), '-o', str(o)]) == 0
    stamps = [frame.stamp_ns for frame, _ in read_frames(ins[0])]
    assert stamps == [frame.stamp_ns for frame, _ in read_frames(ins[1])]
    for o in outs:
        for msgs in (_rosbags_messages(o), _mcap_messages(o)):
            clouds = [m for t, _, _, m in msgs if t == OUTPUT_CLOUD]
            assert [convert.stamp_to_ns(m.header.stamp) for m in clouds] == stamps
            assert all(m.header.frame_id.endswith('optical_frame') for m in clouds)


def test_cloud_typestore_matches_jazzy() -> None:
    """The small store written into output bags defines the cloud exactly as Jazzy does."""
    from endeff_ros.bag.process import CLOUD_TYPE, cloud_typestore
    from endeff_ros.bag.reader import typestore

    small, jazzy = cloud_typestore(), typestore()
    assert small.generate_msgdef(CLOUD_TYPE, ros_version=2) == jazzy.generate_msgdef(
        CLOUD_TYPE, ros_version=2)
    assert small.hash_rihs01(CLOUD_TYPE) == jazzy.hash_rihs01(CLOUD_TYPE)


def test_cloud_cdr_equals_the_node_cloud() -> None:
    """The cloud process writes (rosbags) is the node's cloud message (rclpy), field by field."""
    from endeff_ros.bag.process import CLOUD_TYPE, cloud_cdr, cloud_typestore
    from endeff_ros.core.types import Track

    rng = np.random.default_rng(3)
    ts = cloud_typestore()
    for n in (0, 1, 5):
        tracks = [Track(id=int(i), entity=i % 2, position=rng.normal(size=3), geodesic=0.4 + i,
                        confidence=0.8, state=i % 2, age=3, path=np.zeros((2, 3)))
                  for i in range(n)]
        stamp = 1_700_000_000_123_456_789 + n
        ours = ts.deserialize_cdr(cloud_cdr(stamp, 'cam_optical', tracks), CLOUD_TYPE)
        node = ts.deserialize_cdr(convert.serialize(convert.tracks_to_cloud(
            convert.make_header(stamp, 'cam_optical'), tracks)), CLOUD_TYPE)
        assert ours.header == node.header
        assert [(f.name, f.offset, f.datatype, f.count) for f in ours.fields] == [
            (f.name, f.offset, f.datatype, f.count) for f in node.fields]
        for key in ('height', 'width', 'is_bigendian', 'point_step', 'row_step', 'is_dense'):
            assert getattr(ours, key) == getattr(node, key), key
        assert ours.data.tobytes() == node.data.tobytes()
