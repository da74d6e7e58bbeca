"""``endeff eval``: both estimators scored per bag, spec JSON report, table, plots."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from bag_helpers import (
    BagSpec,
    FakeTracker,
    bench_like_spec,
    fake_estimate_frame,
    write_bag,
)

from endeff_ros.cli import main as cli_main
from endeff_ros.evaluate import evaluate_bags, format_table

SPEC_METHOD_KEYS = {'recall', 'mean_error_m', 'fpr'}


def _check_spec_form(report: dict[str, Any]) -> None:
    """The contract's report keys and types (extra keys are allowed)."""
    assert {'sequences', 'overall'} <= set(report)
    for seq in report['sequences']:
        assert {'bag', 'frames', 'scored_frames', 'temporal', 'single_frame'} <= set(seq)
        assert isinstance(seq['bag'], str)
        assert isinstance(seq['frames'], int) and isinstance(seq['scored_frames'], int)
        for m in ('temporal', 'single_frame'):
            assert set(seq[m]) == SPEC_METHOD_KEYS
    for m in ('temporal', 'single_frame'):
        assert set(report['overall'][m]) == SPEC_METHOD_KEYS


def _lagging_estimate(frame: Any, params: Any = None) -> Any:
    """Single-frame fake that also reports a far-away false positive."""
    est = fake_estimate_frame(frame, params)

    class _Est:
        def positions(self) -> np.ndarray:
            return np.vstack([est.positions(), [[5.0, 5.0, 5.0]]])

    return _Est()


def test_scores_bags_of_both_storages(tmp_path: Path) -> None:
    write_bag(tmp_path / 'data' / 'mcap' / 'seq_a', BagSpec(frames=8, drop_color={4}))
    write_bag(tmp_path / 'data' / 'sqlite3' / 'seq_b',
              BagSpec(frames=6, storage='sqlite3', gt_frames={1, 2, 5}))
    report, results = evaluate_bags([tmp_path / 'data'], estimate_fn=_lagging_estimate,
                                    tracker_factory=FakeTracker)
    _check_spec_form(report)
    seqs = {s['bag']: s for s in report['sequences']}
    assert set(seqs) == {'seq_a', 'seq_b'}
    assert (seqs['seq_a']['frames'], seqs['seq_a']['scored_frames']) == (8, 8)
    assert (seqs['seq_b']['frames'], seqs['seq_b']['scored_frames']) == (6, 3)
    for s in seqs.values():
        # Blob centroids hit every ground-truth point (wrong-frame matching would not: the
        # points move about 0.15 m per frame).
        assert s['temporal']['recall'] == 1.0 and s['temporal']['fpr'] == 0.0
        assert 0.0 < s['temporal']['mean_error_m'] < 0.03
        # The single-frame fake adds one false positive to three true ones: FPR 1/4.
        assert s['single_frame']['recall'] == 1.0
        assert s['single_frame']['fpr'] == pytest.approx(0.25)
        assert len(s['per_frame']['temporal_recall']) == s['scored_frames']
        assert len(s['per_frame']['stamp_ns']) == s['scored_frames']
        # Per frame: no temporal false positive, the single-frame fake's one in every frame.
        assert s['per_frame']['temporal_false_positives'] == [0] * s['scored_frames']
        assert s['per_frame']['single_frame_false_positives'] == [1] * s['scored_frames']
    assert report['overall']['single_frame']['fpr'] == pytest.approx(0.25)
    assert report['failed'] == []
    table = format_table(report)
    assert 'seq_a' in table and 'overall' in table and 'single-frame' in table


def test_ground_truth_needs_exact_stamp(tmp_path: Path) -> None:
    write_bag(tmp_path / 'off', BagSpec(frames=4, gt_stamp_offset_ns=1))
    report, _ = evaluate_bags([tmp_path / 'off'], estimate_fn=fake_estimate_frame,
                              tracker_factory=FakeTracker)
    seq = report['sequences'][0]
    assert seq['frames'] == 4 and seq['scored_frames'] == 0
    assert seq['temporal']['recall'] is None  # undefined, not 0
    assert seq['read_stats']['gt_unmatched'] == 4


def test_duplicate_names_and_failures(tmp_path: Path) -> None:
    write_bag(tmp_path / 'mcap' / 'seq', BagSpec(frames=3))
    write_bag(tmp_path / 'sqlite3' / 'seq', BagSpec(frames=3, storage='sqlite3'))
    write_bag(tmp_path / 'bad' / 'enc', BagSpec(frames=3, depth_encoding='8UC1'))
    report, _ = evaluate_bags([tmp_path / 'mcap', tmp_path / 'sqlite3', tmp_path / 'bad',
                               tmp_path / 'missing'], estimate_fn=fake_estimate_frame,
                              tracker_factory=FakeTracker)
    assert [s['bag'] for s in report['sequences']] == ['mcap/seq', 'sqlite3/seq']
    errors = {Path(f['bag']).name: f['error'] for f in report['failed']}
    assert set(errors) == {'enc', 'missing'}
    assert '8UC1' in errors['enc'] and str(tmp_path / 'bad' / 'enc') in errors['enc']
    assert 'no such file' in errors['missing']


def test_groups_use_synth_names(tmp_path: Path) -> None:
    from endeff_ros import synth
    groups = synth.GROUPS
    name = groups['occlusion'][0]
    write_bag(tmp_path / name, BagSpec(frames=3))
    write_bag(tmp_path / 'unrelated', BagSpec(frames=3))
    report, _ = evaluate_bags([tmp_path], estimate_fn=fake_estimate_frame,
                              tracker_factory=FakeTracker)
    assert list(report['groups']) == ['occlusion']
    assert report['groups']['occlusion']['sequences'] == [name]
    assert report['groups']['occlusion']['temporal']['recall'] == 1.0


def _patch_core(monkeypatch: pytest.MonkeyPatch, seen: list[Any]) -> None:
    import endeff_ros.core.single_frame as sf
    import endeff_ros.core.tracker as tr

    def estimate(frame: Any, params: Any = None, **_: Any) -> Any:  # background=...
        seen.append(params)
        return fake_estimate_frame(frame, params)

    monkeypatch.setattr(sf, 'estimate_frame', estimate)
    monkeypatch.setattr(tr, 'Tracker', FakeTracker)


def test_cli_json_plots_params(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                               capsys: pytest.CaptureFixture[str]) -> None:
    seen: list[Any] = []
    _patch_core(monkeypatch, seen)
    write_bag(tmp_path / 'bags' / 'good', BagSpec(frames=5))
    write_bag(tmp_path / 'bags' / 'noinfo', BagSpec(frames=5, info_every=0))
    params = tmp_path / 'p.yaml'
    params.write_text('endeff_node:\n  ros__parameters:\n    band_delta: 0.09\n')
    out_json = tmp_path / 'report.json'
    status = cli_main(['eval', str(tmp_path / 'bags'), '--json', str(out_json), '--plots',
                       str(tmp_path / 'plots'), '--params', str(params)])
    cap = capsys.readouterr()
    assert status == 1  # one bag failed, the other was scored
    report = json.loads(out_json.read_text(), parse_constant=lambda c: pytest.fail(c))
    _check_spec_form(report)
    assert [s['bag'] for s in report['sequences']] == ['good']
    assert report['sequences'][0]['temporal']['recall'] == 1.0
    assert 'noinfo' in report['failed'][0]['error']
    assert 'FAILED' in cap.err and 'noinfo' in cap.err
    assert 'good' in cap.out and 'overall' in cap.out
    assert 'benchmark contract' in cap.err  # the topic choice is stated
    assert seen and all(p.band_delta == 0.09 for p in seen)
    assert report['params']['band_delta'] == 0.09
    for name in ('per_frame_recall.png', 'summary_bars.png'):
        assert (tmp_path / 'plots' / name).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert cli_main(['eval', str(tmp_path / 'bags' / 'good')]) == 0


def test_eval_does_not_import_rclpy(tmp_path: Path) -> None:
    write_bag(tmp_path / 'b', BagSpec(frames=2))
    code = (
        'import sys\n'
        f'sys.path.insert(0, {str(Path(__file__).parent)!r})\n'
        'from bag_helpers import FakeTracker, fake_estimate_frame\n'
        'from endeff_ros.evaluate import evaluate_bags\n'
        f'r, _ = evaluate_bags([{str(tmp_path / "b")!r}], estimate_fn=fake_estimate_frame,\n'
        '                      tracker_factory=FakeTracker)\n'
        'assert r["sequences"][0]["frames"] == 2, r\n'
        'bad = sorted(m for m in sys.modules if m.split(".")[0] in ("rclpy", "rosidl_parser",\n'
        '             "sensor_msgs", "std_msgs", "visualization_msgs"))\n'
        'assert not bad, bad\n')
    subprocess.run([sys.executable, '-c', code], check=True, timeout=120)


def test_parallel_jobs_same_result(tmp_path: Path) -> None:
    for i in range(2):
        write_bag(tmp_path / f's{i}', BagSpec(frames=4, storage=('mcap', 'sqlite3')[i]))
    kw = dict(estimate_fn=fake_estimate_frame, tracker_factory=FakeTracker)
    one, _ = evaluate_bags([tmp_path], jobs=1, **kw)
    two, _ = evaluate_bags([tmp_path], jobs=2, **kw)
    strip = [{k: v for k, v in s.items() if k != 'seconds'} for s in one['sequences']]
    assert strip == [{k: v for k, v in s.items() if k != 'seconds'} for s in two['sequences']]


def test_real_estimators_on_foreign_bag(tmp_path: Path) -> None:
    """The real core on a bag this project did not write: runs, report in the spec's form."""
    write_bag(tmp_path / 'blobs', bench_like_spec(frames=5))
    report, _ = evaluate_bags([tmp_path / 'blobs'])
    _check_spec_form(report)
    seq = report['sequences'][0]
    assert report['failed'] == [] and seq['frames'] == 5 and seq['scored_frames'] == 5
    for m in ('temporal', 'single_frame'):
        assert 0.0 <= seq[m]['recall'] <= 1.0 and 0.0 <= seq[m]['fpr'] <= 1.0


def test_real_estimators_on_synth_bags(tmp_path: Path) -> None:
    """``endeff synth --quick`` bags, both storages, scored by the real estimators."""
    out = tmp_path / 'synth'
    names = ['jumping_jacks', 'star']
    assert cli_main(['synth', '--out', str(out), '--quick', '--only', ','.join(names)]) == 0
    bags = [out / st / n for st in ('mcap', 'sqlite3') for n in names]
    report, _ = evaluate_bags(bags)
    _check_spec_form(report)
    assert report['failed'] == []
    assert len(report['sequences']) == 4
    by = {s['bag']: s for s in report['sequences']}
    for n in names:
        a, b = by[f'mcap/{n}'], by[f'sqlite3/{n}']
        assert a['scored_frames'] > 0 and a['frames'] == b['frames']
        assert a['temporal'] == b['temporal']  # same content, either storage
        assert not math.isnan(a['temporal']['recall'])
    assert set(report['groups']) == {'no_occlusion', 'generic'}


class _TrackerWithStrays(FakeTracker):
    """FakeTracker plus two far-away tracks per frame: one detected, one predicted."""

    def update(self, frame: Any) -> Any:
        from endeff_ros.core.types import Track

        result = super().update(frame)
        for k, state in enumerate((Track.DETECTED, Track.PREDICTED)):
            stray = np.array([5.0, 5.0, 5.0 + k])
            result.tracks.append(Track(id=100 + k, entity=0, position=stray, geodesic=1.0,
                                       confidence=0.5, state=state, age=self.frames,
                                       path=np.zeros((1, 3))))
        return result


def test_predicted_false_positives_are_counted(tmp_path: Path) -> None:
    write_bag(tmp_path / 'seq', BagSpec(frames=5, gt_frames={0, 1, 3}))
    report, _ = evaluate_bags([tmp_path / 'seq'], estimate_fn=fake_estimate_frame,
                              tracker_factory=_TrackerWithStrays)
    counts = report['sequences'][0]['counts']['temporal']
    # Two strays in each of the 3 scored frames; one of each pair is a predicted track.
    assert counts['predicted_false_positives'] == 3
    assert report['sequences'][0]['temporal']['fpr'] == pytest.approx(2 / 5)  # per frame, Eq. 12


def _set_custom_data(bag: Path, custom: dict[str, str]) -> None:
    """Add rosbag2 ``custom_data`` to a bag's metadata.yaml, as a recorder would."""
    import yaml

    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())
    meta['rosbag2_bagfile_information']['custom_data'] = custom
    (bag / 'metadata.yaml').write_text(yaml.safe_dump(meta))


def _miss_second_blob(frame: Any, params: Any = None) -> Any:
    """Single-frame fake that misses the blob second from the left (ground-truth id 1)."""
    est = fake_estimate_frame(frame, params)

    class _Est:
        def positions(self) -> np.ndarray:
            pos = est.positions()
            return np.delete(pos, np.argsort(pos[:, 0])[1], axis=0)

    return _Est()


def test_attribute_groups_and_kinds(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    people = dict(width=160, n_blobs=5)  # ids 0-4: head, hands, feet; all blobs in view
    write_bag(tmp_path / 'a', BagSpec(frames=4, **people))
    write_bag(tmp_path / 'b', BagSpec(frames=4, storage='sqlite3', **people))
    write_bag(tmp_path / 'c', BagSpec(frames=4, **people))
    write_bag(tmp_path / 'd', BagSpec(frames=4, **people))
    _set_custom_data(tmp_path / 'a', {'endeff.attributes': json.dumps(
        {'view': 'side', 'camera_height_m': 0.8, 'distance_m': 3.0, 'split': 'dev',
         'people': 1, 'truncated': False, 'markers': [1, 2]}), 'other.key': 'x'})
    _set_custom_data(tmp_path / 'b', {'endeff.attributes': json.dumps(
        {'view': 'front', 'camera_height_m': 1.6, 'split': 'test', 'people': 1})})
    _set_custom_data(tmp_path / 'd', {'endeff.attributes': '{"view": '})
    report, _ = evaluate_bags([tmp_path], estimate_fn=_miss_second_blob,
                              tracker_factory=FakeTracker)
    err = capsys.readouterr().err
    seqs = {s['bag']: s for s in report['sequences']}
    assert set(seqs) == {'a', 'b', 'c', 'd'} and report['failed'] == []
    assert seqs['a']['attributes']['view'] == 'side' and seqs['c']['attributes'] == {}
    # The malformed value is a warning naming the bag; the bag is still scored.
    assert seqs['d']['attributes'] == {} and str(tmp_path / 'd') in seqs['d']['attribute_warning']
    assert 'warning' in err and str(tmp_path / 'd') in err
    groups = report['groups']
    assert groups['view=side']['sequences'] == ['a']
    assert groups['view=side']['attribute'] == 'view'
    assert groups['split=test']['sequences'] == ['b']
    assert list(k for k in groups if k.startswith('camera_height_m')) == [
        'camera_height_m=<1', 'camera_height_m=1-1.6']
    assert groups['distance_m=2-3.5']['sequences'] == ['a']
    assert groups['truncated=false']['sequences'] == ['a']
    assert not any(k.startswith('markers') for k in groups)  # a list is not groupable
    # People bags: per-kind recall; the single-frame fake misses one of the two hands.
    for name in ('a', 'b'):
        kinds = seqs[name]['kinds']
        assert {k: v['recall'] for k, v in kinds['temporal'].items()} == {
            'head': 1.0, 'hand': 1.0, 'foot': 1.0}
        assert {k: v['recall'] for k, v in kinds['single_frame'].items()} == {
            'head': 1.0, 'hand': 0.5, 'foot': 1.0}
        assert kinds['single_frame']['hand']['gt_points'] == 8
    # Without the people attribute (and not a paper person sequence) the ids are 'other'.
    assert list(seqs['c']['kinds']['temporal']) == ['other']
    assert report['kinds']['single_frame']['hand']['recall'] == 0.5
    assert report['kinds']['single_frame']['other']['recall'] == pytest.approx(0.8)
    assert groups['view=front']['kinds']['single_frame']['hand']['recall'] == 0.5
    json.dumps(report, allow_nan=False)
    table = format_table(report)
    assert '-- view ' in table and '-- camera_height_m ' in table
    assert 'split' in table.splitlines()[1]
    assert any(line.startswith('a ') and ' dev ' in line for line in table.splitlines())
    assert 'per kind' in table and 'hand' in table


def test_paper_person_sequences_have_kinds(tmp_path: Path) -> None:
    people = dict(frames=2, width=160, n_blobs=5)
    for name in ('jumping_jacks', 'two_people', 'chair', 'punching'):
        write_bag(tmp_path / name, BagSpec(**people))
    # The attribute wins over the name: no people in this 'punching'.
    _set_custom_data(tmp_path / 'punching', {'endeff.attributes': '{"people": 0}'})
    report, _ = evaluate_bags([tmp_path], estimate_fn=fake_estimate_frame,
                              tracker_factory=FakeTracker)
    kinds = {s['bag']: list(s['kinds']['temporal']) for s in report['sequences']}
    assert kinds == {'jumping_jacks': ['head', 'hand', 'foot'],
                     'two_people': ['head', 'hand', 'foot'],
                     'chair': ['other'], 'punching': ['other']}


def test_unwritable_json_fails_before_any_bag_is_read(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    (tmp_path / 'file').write_text('not a folder')
    with pytest.raises(SystemExit) as exc:
        cli_main(['eval', str(tmp_path / 'no_such_bag'), '--json',
                  str(tmp_path / 'file' / 'report.json')])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert 'report.json' in err and 'no_such_bag' not in err  # the bag was never looked at


def test_progress_counts_every_frame(tmp_path: Path) -> None:
    from endeff_ros.evaluate import evaluate_bag

    write_bag(tmp_path / 'seq', BagSpec(frames=7))
    seen: list[int] = []
    evaluate_bag(tmp_path / 'seq', estimate_fn=fake_estimate_frame, tracker_factory=FakeTracker,
                 progress=seen.append)
    assert seen == [1] * 7


def test_plots_without_matplotlib_are_reported(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    write_bag(tmp_path / 'seq', BagSpec(frames=3))
    _patch_core(monkeypatch, [])
    monkeypatch.setitem(sys.modules, 'matplotlib', None)  # import matplotlib -> ImportError
    assert cli_main(['eval', str(tmp_path / 'seq'), '--plots', str(tmp_path / 'plots')]) == 0
    assert 'no plots' in capsys.readouterr().err


def test_labels_inside_the_box_are_counted(tmp_path: Path) -> None:
    """The report says how many ground-truth points lie inside the foreground box: blob 2
    (x 0.35-0.65 m) lies beyond a box ending at x = 0.2 m, blobs 0 and 1 (x <= 0.15) inside."""
    from endeff_ros.core.params import EndeffParams

    write_bag(tmp_path / 'a', BagSpec(frames=6, gt_frames={0, 2, 3, 5}))
    default, _ = evaluate_bags([tmp_path / 'a'], estimate_fn=_lagging_estimate,
                               tracker_factory=FakeTracker)
    assert default['labels_in_box'] == {'points': 12, 'inside': 12, 'fraction': 1.0}
    narrow, _ = evaluate_bags([tmp_path / 'a'], params=EndeffParams(box_max_x=0.2),
                              estimate_fn=_lagging_estimate, tracker_factory=FakeTracker)
    assert narrow['sequences'][0]['labels_in_box'] == {'points': 12, 'inside': 8,
                                                       'fraction': 0.6667}
    assert narrow['labels_in_box']['inside'] == 8
    assert '8 of 12 (66.7 %)' in format_table(narrow)


def test_labels_with_depth_readings_are_counted_as_seen(tmp_path: Path) -> None:
    """Every blob of the test bag is drawn at its label (seen); blobs one pixel wide are no
    surface (fewer than 3 readings): then nothing is seen and the seen recall is undefined,
    while the scores stay what they were."""
    write_bag(tmp_path / 'a', BagSpec(frames=6, gt_frames={0, 2, 3, 5}))
    write_bag(tmp_path / 'b', BagSpec(frames=6, gt_frames={0, 2, 3, 5}, blob_px=0))
    drawn, _ = evaluate_bags([tmp_path / 'a'], estimate_fn=_lagging_estimate,
                             tracker_factory=FakeTracker)
    seq = drawn['sequences'][0]
    assert seq['labels_seen']['seen'] == seq['labels_seen']['points'] == 12
    for m in ('temporal', 'single_frame'):
        counts = seq['counts'][m]
        assert counts['seen_tp'] == counts['tp'] > 0
        assert seq['labels_seen']['recall'][m] == pytest.approx(counts['tp'] / 12)
    assert drawn['labels_seen']['fraction'] == 1.0
    assert 'seen): 12 of 12 (100.0 %)' in format_table(drawn)
    dots, _ = evaluate_bags([tmp_path / 'b'], estimate_fn=_lagging_estimate,
                            tracker_factory=FakeTracker)
    assert dots['labels_seen']['seen'] == 0
    assert dots['labels_seen']['recall'] == {'temporal': None, 'single_frame': None}
    assert dots['sequences'][0]['single_frame']['recall'] == seq['single_frame']['recall']
