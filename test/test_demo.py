"""The demo's scoring and table (no DDS: replay records are built by hand)."""

from __future__ import annotations

import numpy as np

from tools import demo


def _record(stamps, clouds):
    return {'depth_sent': stamps, 'outputs': {'node': clouds}}


def test_score_record_matches_ground_truth_by_stamp():
    gt = {1: np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 2.0]]), 2: np.array([[0.0, 0.0, 2.0]])}
    clouds = {1: {'x': [0.01, 5.0], 'y': [0.0, 0.0], 'z': [2.0, 2.0]}}  # frame 2: no cloud
    scorer = demo.score_record(_record([1, 2, 3], clouds), gt)
    assert scorer.frames == 3 and scorer.scored_frames == 2
    result = scorer.result()
    assert result.recall == np.mean([0.5, 0.0])
    assert result.fpr == np.mean([0.5, 0.0])
    assert abs(result.mean_error_m - 0.01) < 1e-9


def test_report_and_table():
    row = {'bag': 'seq', 'frames': 3, 'scored_frames': 2, 'clouds': 2, 'missing_clouds': 1,
           'temporal': {'recall': 0.5, 'mean_error_m': 0.01, 'fpr': None},
           'single_frame': {'recall': 0.25, 'mean_error_m': 0.02, 'fpr': 0.1}}
    report = demo.build_report([row], [{'bag': 'bad', 'error': 'boom'}])
    assert set(report['overall']) == {'temporal', 'single_frame'}
    assert report['overall']['temporal']['recall'] == 0.5
    assert report['overall']['temporal']['fpr'] is None
    table = demo.format_table(report)
    assert 'seq' in table and '0.500' in table and 'FAILED bad: boom' in table


def test_find_demo_bags_prefers_mcap(tmp_path):
    for storage in ('mcap', 'sqlite3'):
        for name in ('b', 'a'):
            d = tmp_path / storage / name
            d.mkdir(parents=True)
            (d / 'metadata.yaml').write_text('rosbag2_bagfile_information: {}\n')
    bags = demo.find_demo_bags(tmp_path)
    assert [b.parent.name for b in bags] == ['mcap', 'mcap']
    assert [b.name for b in bags] == ['a', 'b']
    assert [b.name for b in demo.find_demo_bags(tmp_path, only='b')] == ['b']
