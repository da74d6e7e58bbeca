"""One-to-one assignment: the Hungarian step of the update (Section 5.2) and of the scoring
(Section 6.1)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import min_weight_full_bipartite_matching

if TYPE_CHECKING:
    import numpy.typing as npt


def min_cost_assignment(cost: npt.ArrayLike,
                        ) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Rows and columns of a one-to-one assignment of minimum total cost on a dense (N, M)
    matrix of finite costs: min(N, M) pairs, rows in increasing order (the result of
    ``scipy.optimize.linear_sum_assignment``).

    Solved as a minimum-weight full bipartite matching by ``scipy.sparse.csgraph``, which the
    graph code imports anyway: ``scipy.optimize`` solves the same problem but costs about
    0.25 s to import, a twentieth of ``endeff process`` on a bag of 300 frames. csgraph reads
    a zero entry as no edge, so the costs are shifted to be at least 1; every full matching
    has min(N, M) edges, so a constant shift does not change which one is cheapest.
    """
    c = np.asarray(cost, dtype=np.float64)
    if c.ndim != 2:
        msg = f'cost must be a 2-D matrix, got shape {c.shape}'
        raise ValueError(msg)
    if c.size == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    if not np.all(np.isfinite(c)):
        msg = 'cost holds non-finite values'
        raise ValueError(msg)
    n, m = c.shape
    weights = sparse.csr_matrix(((c - c.min() + 1.0).ravel(),
                                 np.tile(np.arange(m, dtype=np.int32), n),
                                 np.arange(0, n * m + 1, m, dtype=np.int32)), shape=(n, m))
    rows, cols = min_weight_full_bipartite_matching(weights)
    order = np.argsort(rows, kind='stable')
    return rows[order].astype(np.intp), cols[order].astype(np.intp)
