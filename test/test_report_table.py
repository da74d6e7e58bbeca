"""tools.report_table: one markdown row per group, the labels seen beside the scores."""

from __future__ import annotations

from tools.report_table import table


def _score(recall: float, fpr: float) -> dict[str, float]:
    return {'recall': recall, 'mean_error_m': 0.05, 'fpr': fpr}


def test_rows_carry_the_seen_share_and_the_recall_over_it() -> None:
    seen = {'fraction': 0.8, 'recall': {'temporal': 0.75, 'single_frame': 0.5}}
    report = {
        'sequences': [{}, {}],
        'overall': {'temporal': _score(0.6, 0.1), 'single_frame': _score(0.4, 0.2)},
        'labels_seen': seen,
        'groups': {'view=side': {'attribute': 'view', 'sequences': ['a'],
                                 'temporal': _score(0.5, 0.3),
                                 'single_frame': _score(0.3, 0.4)},
                   'jumping': {'sequences': ['b'], 'temporal': _score(1.0, 0.0)}},
        'kinds': {'temporal': {'hand': {'recall': 0.5, 'mean_error_m': 0.06,
                                        'seen_recall': 0.625}},
                  'single_frame': {'hand': {'recall': 0.25, 'mean_error_m': None}}},
    }
    lines = table('dev', report).splitlines()
    overall = ('| **overall** | 2 | 0.600 | 5.0 cm | 0.100 | 0.400 | 5.0 cm | 0.200 | 0.800 '
               '| 0.750 |')
    assert overall in lines
    # An attribute group without labels_seen (an older report) shows dashes; the paper
    # suite's named groups (no attribute) are left out.
    assert '| `view=side` | 1 | 0.500 | 5.0 cm | 0.300 | 0.300 | 5.0 cm | 0.400 | - | - |' in lines
    assert not any('jumping' in line for line in lines)
    assert '| hand | 0.500 | 6.0 cm | 0.250 | - | 0.625 |' in lines
