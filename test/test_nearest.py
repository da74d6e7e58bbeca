"""Brute-force nearest point against a KD-tree."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from endeff_ros.core.nearest import nearest_point


@pytest.mark.parametrize('n_queries', [1, 5, 64, 65, 200])
def test_nearest_point_matches_a_kd_tree(n_queries):
    rng = np.random.default_rng(n_queries)
    points = rng.uniform(-1, 1, (1500, 3)) + [0, 0, 2.5]
    queries = rng.uniform(-1.2, 1.2, (n_queries, 3)) + [0, 0, 2.5]
    dist, index = nearest_point(points, queries)
    want_dist, want_index = cKDTree(points).query(queries)
    np.testing.assert_array_equal(index, want_index)
    np.testing.assert_allclose(dist, want_dist, rtol=1e-12)


def test_nearest_point_of_no_queries_and_of_a_point_in_the_cloud():
    points = np.array([[0.0, 0.0, 1.0], [0.5, 0.0, 1.0], [0.0, 0.5, 2.0]])
    dist, index = nearest_point(points, np.zeros((0, 3)))
    assert dist.shape == (0,) and index.shape == (0,)
    dist, index = nearest_point(points, points[[2, 0]] + [0.01, 0.0, 0.0])
    assert index.tolist() == [2, 0]
    np.testing.assert_allclose(dist, [0.01, 0.01])
