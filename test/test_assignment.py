"""The one-to-one assignment used by the update (Section 5.2) and the scoring (Section 6.1)."""

import itertools

import numpy as np
import pytest

from endeff_ros.core.assignment import min_cost_assignment


def _brute_force_cost(cost):
    """Minimum total cost over every one-to-one assignment of the smaller side."""
    n, m = cost.shape
    if n <= m:
        return min(sum(cost[i, j] for i, j in zip(range(n), cols))
                   for cols in itertools.permutations(range(m), n))
    return _brute_force_cost(cost.T)


@pytest.mark.parametrize('shape', [(1, 1), (3, 3), (2, 5), (5, 2), (4, 6), (6, 4)])
def test_the_assignment_is_one_to_one_and_of_minimum_cost(shape):
    rng = np.random.default_rng(sum(shape))
    for _ in range(20):
        cost = rng.random(shape)
        cost[rng.random(shape) < 0.4] = 0.0  # ties and zero entries (no similarity)
        rows, cols = min_cost_assignment(cost)
        assert len(rows) == len(cols) == min(shape)
        assert len(set(rows.tolist())) == len(rows) and len(set(cols.tolist())) == len(cols)
        assert np.all(np.diff(rows) > 0)
        assert cost[rows, cols].sum() == pytest.approx(_brute_force_cost(cost))


def test_negative_costs_maximise_a_similarity():
    sim = np.array([[0.9, 0.8], [0.85, 0.1]])
    rows, cols = min_cost_assignment(-sim)
    assert list(zip(rows.tolist(), cols.tolist())) == [(0, 1), (1, 0)]


def test_empty_and_bad_input():
    rows, cols = min_cost_assignment(np.zeros((0, 3)))
    assert rows.size == cols.size == 0
    with pytest.raises(ValueError, match='2-D'):
        min_cost_assignment(np.zeros(3))
    with pytest.raises(ValueError, match='non-finite'):
        min_cost_assignment(np.array([[np.nan, 1.0]]))
