"""``endeff eval``'s confusion matrix of the published kinds (endeff_ros/kind_eval.py)."""

from __future__ import annotations

import numpy as np

from endeff_ros.core.types import Track
from endeff_ros.evaluate import METHODS, SequenceResult, build_report, format_table
from endeff_ros.kind_eval import KindConfusion, confusion_group
from endeff_ros.scoring import SequenceScorer, score_frame


def _track(tid: int, position: list[float], kind: int) -> Track:
    return Track(id=tid, entity=0, position=np.array(position), geodesic=0.8, confidence=1.0,
                 state=Track.DETECTED, age=3, kind=kind)


def test_matched_ends_count_under_their_labels_kind_the_others_as_unmatched():
    labels = np.array([[0.0, -0.5, 3.0], [0.5, 0.0, 3.0], [-0.5, 0.0, 3.0], [0.1, 1.0, 3.0]])
    kinds = np.array(['head', 'hand', 'hand', 'foot'])
    tracks = [_track(1, [0.02, -0.5, 3.0], Track.KIND_HEAD),   # right
              _track(2, [0.5, 0.03, 3.0], Track.KIND_FOOT),    # a hand taken for a foot
              _track(3, [0.1, 0.98, 3.0], Track.KIND_FOOT),    # right
              _track(4, [-3.0, 0.0, 3.0], Track.KIND_HAND)]    # no label near: unmatched
    confusion = KindConfusion()
    confusion.add(tracks, kinds, score_frame([t.position for t in tracks], labels))
    c = confusion.to_json()
    assert c['rows'] == ['head', 'hand', 'foot', 'other', 'unmatched']
    assert c['columns'] == ['other', 'head', 'hand', 'foot']
    assert c['counts'] == [[0, 1, 0, 0], [0, 0, 0, 1], [0, 0, 0, 1], [0, 0, 0, 0],
                           [0, 0, 1, 0]]
    assert c['matched'] == 3 and c['accuracy'] == round(2 / 3, 4)
    assert c['per_kind'] == {'head': 1.0, 'hand': 0.0, 'foot': 1.0, 'other': None}
    assert c['other_fraction'] == 0.0
    # Frames whose labels have no ids (kinds None) or no ground truth are not counted.
    confusion.add(tracks, None, score_frame([t.position for t in tracks], labels))
    confusion.add(tracks, kinds, None)
    assert confusion.to_json()['counts'] == c['counts']


def test_groups_add_counts_and_the_table_prints_the_matrix():
    a, b = KindConfusion(), KindConfusion()
    a.counts[0, 1] = 9  # heads right
    a.counts[1, 3] = 1  # a hand taken for a foot
    b.counts[3, 0] = 4  # a chair's legs, other
    b.counts[4, 0] = 2  # and two unmatched ends of it, other too
    total = confusion_group([a, b])
    assert total['matched'] == 14 and total['accuracy'] == round(13 / 14, 4)
    assert total['other_fraction'] == round(6 / 16, 4)

    def result(name: str, confusion: KindConfusion) -> SequenceResult:
        return SequenceResult(name=name, path=name,
                              scorers={m: SequenceScorer() for m in METHODS},
                              recalls={m: [] for m in METHODS},
                              false_positives={m: [] for m in METHODS},
                              kind_confusion=confusion)

    report = build_report([result('a', a), result('b', b)])
    assert report['kind_confusion']['counts'] == total['counts']
    assert report['sequences'][0]['kind_confusion']['matched'] == 10
    text = format_table(report)
    assert 'published kind' in text
    assert 'kind right for 92.9 % of 14 matched ends' in text
