"""Section 4.1: narrow-band level-set expansion (Eqs. 1-4) and the split into sub-bands.

The foreground cloud is organised into bands by growing a level set from the root: each
iteration adds the *narrow band* of points closer than δ_L to the current contour (proximity,
Eq. 2) that have at least η_L neighbours within δ_L (density, Eq. 3); the next contour is the
part of the new band farther than ¾δ_L from the old one (Eq. 4). All neighbourhoods come from
one sparse radius graph, so an iteration is a few vectorised operations over the contour's
neighbours; Python loops run once per band, never per point.

Sub-bands (the paper leaves the split open): a band is cut into its connected pieces, with
connectivity at the band distance δ_L (the caller's ``connect``), so two legs or an arm beside
the torso at the same level become different sub-bands (cutting at λ instead, 0.06 against 0.08
m, found more hands and more false ends on the mocap dev split: docs/results.md); a piece with
more than ``subband_max_points`` points is cut further into equal slices along its main axis,
so a wide torso band does not collapse into one node whose centroid lies far from where the
limbs attach. Connectivity matches the paper's "context" of a sub-band; the size cap is the
paper's own criterion.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from . import kernels

try:  # scipy's counting sort of COO entries by row (private; see group_rows)
    from scipy.sparse._sparsetools import coo_tocsr as _coo_tocsr
except ImportError:  # pragma: no cover - depends on the scipy build
    _coo_tocsr = None
try:  # the kernel of scipy's weak components (private; see Neighbours.components)
    from scipy.sparse.csgraph._traversal import (
        _connected_components_undirected as _weak_components,
    )
except ImportError:  # pragma: no cover - depends on the scipy build
    _weak_components = None


def _kernel_works() -> bool:
    """Whether the private kernel takes the arguments Neighbours.components gives it and
    labels a small graph as the public call does (its signature is scipy's to change)."""
    # Pairs 0-1 and 2-3 of five points: parts {0, 1}, {2, 3}, {4}, labelled 0, 1, 2.
    indptr = np.array([0, 1, 1, 2, 2, 2], dtype=np.int32)
    indices = np.array([1, 3], dtype=np.int32)
    t_indptr = np.array([0, 0, 1, 1, 2, 2], dtype=np.int32)
    t_indices = np.array([0, 2], dtype=np.int32)
    labels = np.empty(5, dtype=np.int32)
    try:
        _weak_components(indices, indptr, t_indices, t_indptr, labels)
    except (TypeError, ValueError):  # pragma: no cover - depends on the scipy build
        return False
    return labels.tolist() == [0, 0, 1, 1, 2]


if _weak_components is not None and not _kernel_works():  # pragma: no cover
    _weak_components = None

if TYPE_CHECKING:
    import numpy.typing as npt

UNREACHED = -1


@dataclass(frozen=True)
class Neighbours:
    """All pairs of points closer than a radius, built once per frame.

    ``i``, ``j`` (pairs with i < j) and ``d`` (their distances, metres) serve the sub-band,
    entity and attachment computations; ``indptr``/``indices``/``data`` are the symmetric CSR
    adjacency, and :attr:`padded` the same rows padded to equal length, for the band expansion.
    """

    n: int  # pairs below are sorted by i
    i: npt.NDArray[np.intp]
    j: npt.NDArray[np.intp]
    d: npt.NDArray[np.float64]
    indptr: npt.NDArray[np.intp]
    indices: npt.NDArray[np.intp]
    data: npt.NDArray[np.float64]

    def components(self, keep: npt.NDArray[np.bool_]) -> npt.NDArray[np.intp]:
        """Connected-component label of every point using only the pairs where ``keep``."""
        # Pairs are sorted by i, so the kept pairs form a one-directional CSR directly; weak
        # components of it are the undirected components (and 10x cheaper to compute than
        # on the symmetric matrix).
        # float64 data and int32 indices are what csgraph uses: no conversion copies.
        # Kept pairs by index: numpy gathers through an index array about four times faster
        # than through a boolean mask that keeps about half (docs/design.md, "Speed").
        kept = np.flatnonzero(keep)
        i, j = self.i[kept], self.j[kept]
        indptr = np.zeros(self.n + 1, dtype=np.int32)
        np.cumsum(np.bincount(i, minlength=self.n), out=indptr[1:])
        if _weak_components is not None:
            # What connected_components(directed=True, connection='weak') runs, given the
            # transpose (rows j, columns i in order) from our counting sort instead of a
            # validated matrix and its .T.tocsr(): half the cost, the same labels.
            t_indptr, t_indices, _ = group_rows(self.n, j, i, self.d[kept])
            labels = np.empty(self.n, dtype=np.int32)
            _weak_components(j.astype(np.int32), indptr, t_indices.astype(np.int32),
                             t_indptr.astype(np.int32), labels)
            return labels
        g = sparse.csr_matrix((np.ones(len(kept)), j.astype(np.int32), indptr),
                              shape=(self.n, self.n))
        return csgraph.connected_components(g, directed=True, connection='weak')[1]

    @classmethod
    def build(cls, points: npt.NDArray[np.float64], radius: float, *,
              steep_ratio: float = 0.0, steep_min: float = 0.0,
              colors: npt.NDArray[np.float64] | None = None, color_rgb: float = 0.0,
              color_step: float = 0.0) -> Neighbours:
        """All pairs closer than ``radius``, less those one behind the other when
        ``steep_ratio`` > 0 (:func:`steep_pairs`) and those across a colour edge when
        ``colors`` (N, 3) are given and ``color_rgb`` > 0 (:func:`color_edge_pairs`); both
        are dropped before the adjacency is built, so the cuts cost no second one."""
        n = len(points)
        if n < 2:
            empty_i = np.zeros(0, dtype=np.intp)
            return cls(n, empty_i, empty_i, np.zeros(0), np.zeros(n + 1, dtype=np.intp),
                       empty_i, np.zeros(0))
        # An unbalanced tree builds and answers this query ~20 % faster on these clouds.
        tree = cKDTree(points, balanced_tree=False, compact_nodes=False)
        pairs = tree.query_pairs(radius, output_type='ndarray')
        pi, pj = pairs[:, 0], pairs[:, 1]
        d = np.zeros(len(pi))
        for axis in range(3):  # per coordinate: 1-D gathers are ~4x cheaper than row gathers
            c = np.ascontiguousarray(points[:, axis])
            d += (c[pi] - c[pj]) ** 2
        d = np.maximum(np.sqrt(d, out=d), 1e-9)
        if steep_ratio > 0:
            keep = np.flatnonzero(~steep_pairs(points, pi, pj, d, steep_ratio, steep_min))
            pi, pj, d = pi[keep], pj[keep], d[keep]
        if colors is not None and color_rgb > 0:
            keep = np.flatnonzero(~color_edge_pairs(points, colors, pi, pj, color_rgb, color_step))
            pi, pj, d = pi[keep], pj[keep], d[keep]
        indptr, j, d = group_rows(n, pi, pj, d)
        i = np.repeat(np.arange(n, dtype=np.intp), np.diff(indptr))
        return cls.from_pairs(n, i, j, d)

    @classmethod
    def from_pairs(cls, n: int, i: npt.NDArray[np.intp], j: npt.NDArray[np.intp],
                   d: npt.NDArray[np.float64]) -> Neighbours:
        return cls(n, i, j, d, *symmetric_csr(n, i, j, d))

    def within(self, radius: float) -> Neighbours:
        """The pairs closer than ``radius`` (a smaller radius than the one built with)."""
        keep = np.flatnonzero(self.d < radius)
        return Neighbours.from_pairs(self.n, self.i[keep], self.j[keep], self.d[keep])

    @functools.cached_property
    def padded(self) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.float64]] | None:
        """The adjacency as (N, W) tables of neighbour indices and distances, W the largest
        degree; short rows are padded with index N (one past the last point) and distance
        inf. Gathering rows of it costs two operations where the CSR rows cost nine (the band
        expansion gathers once per band). None when padding would more than triple the
        storage (very uneven degrees): use the CSR arrays then."""
        degree = self.degree()
        width = int(degree.max()) if self.n else 0
        nnz = len(self.indices)
        if width == 0 or self.n * width > 3 * nnz + 1024:
            return None
        # Flat slot of each CSR entry: its row's start in the table plus its rank in the row.
        flat = np.repeat(np.arange(0, self.n * width, width) - self.indptr[:-1], degree)
        flat += np.arange(nnz)
        table = np.full(self.n * width, self.n, dtype=np.intp)
        table[flat] = self.indices
        dist = np.full(self.n * width, np.inf)
        dist[flat] = self.data
        table, dist = table.reshape(self.n, width), dist.reshape(self.n, width)
        return table, dist

    def degree(self) -> npt.NDArray[np.intp]:
        """Number of neighbours of each point."""
        return np.diff(self.indptr)


def steep_pairs(points: npt.NDArray[np.float64], i: npt.NDArray[np.intp],
                j: npt.NDArray[np.intp], d: npt.NDArray[np.float64], ratio: float,
                min_step: float) -> npt.NDArray[np.bool_]:
    """Which pairs ``(i, j)`` (distances ``d``) lie one behind the other: farther apart along
    the viewing ray than both ``min_step`` and ``ratio`` times across it.

    Such a pair joins two surfaces that overlap in the image, a hand or forearm in front of
    the chest and the chest behind it, which the radius graph (δ_L) otherwise makes one
    surface, so the band expansion passes from the chest straight into the hand and the hand
    is no extreme of the graph. A surface seen at incidence θ has neighbours with
    along / across = tan θ, so a ratio of 4 keeps every surface seen within 76 degrees of
    head-on (sensors return few readings beyond 80). "Along the ray" is the difference of
    the two points' ranges from the camera: for neighbours a few centimetres apart at a
    metre or more it equals the separation along the ray through their midpoint to within a
    fraction of a millimetre, and it needs one range per point and 1-D gathers only (a
    fifth of the cost of projecting each pair on its ray).
    """
    along = range_steps(points, i, j)
    # along > ratio * across with across^2 = d^2 - along^2, without the square root.
    return (along > min_step) & (along * along * (1.0 + ratio * ratio) > ratio * ratio * d * d)


def range_steps(points: npt.NDArray[np.float64], i: npt.NDArray[np.intp],
                j: npt.NDArray[np.intp]) -> npt.NDArray[np.float64]:
    """|range(j) - range(i)| of each pair: its step along the viewing ray (:func:`steep_pairs`
    says why the ranges' difference stands for it)."""
    r = np.sqrt(np.einsum('ij,ij->i', points, points))
    return np.abs(r[j] - r[i])


def color_edge_pairs(points: npt.NDArray[np.float64], colors: npt.NDArray[np.float64],
                     i: npt.NDArray[np.intp], j: npt.NDArray[np.intp], rgb: float,
                     min_step: float) -> npt.NDArray[np.bool_]:
    """Which pairs ``(i, j)`` lie across a colour edge: their ``colors`` (N, 3, 0-255 RGB)
    differ by more than ``rgb`` (Euclidean) and their ranges from the camera by more than
    ``min_step`` metres.

    A hand held against the belly touches it: no step along the ray separates the hand's rim
    from the shirt beside it (:func:`steep_pairs` keeps those pairs), but the colours differ.
    The step keeps the pairs of one continuous surface whose colour changes (a pattern, a
    sleeve's edge seen side-on). The rule is off by default: a limb pointing at the camera
    loses its pairs at a sleeve's edge, and a real camera's colour is registered to its
    depth only roughly, so texture and misregistered edges cut real bodies
    (docs/design.md, "Colour edges").
    """
    step = np.flatnonzero(range_steps(points, i, j) > min_step)
    out = np.zeros(len(i), dtype=bool)
    diff = colors[i[step]] - colors[j[step]]
    out[step] = np.einsum('ij,ij->i', diff, diff) > rgb * rgb
    return out


def symmetric_csr(n: int, i: npt.NDArray[np.intp], j: npt.NDArray[np.intp],
                  d: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.intp],
                                                        npt.NDArray[np.intp],
                                                        npt.NDArray[np.float64]]:
    """``(indptr, indices, data)`` of the symmetric (n, n) CSR matrix with ``d`` at (i, j)
    and (j, i) for each pair; rows keep the pairs' order."""
    return group_rows(n, np.concatenate([i, j]), np.concatenate([j, i]), np.concatenate([d, d]))


def group_rows(n: int, rows: npt.NDArray[np.intp], cols: npt.NDArray[np.intp],
               data: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.intp],
                                                        npt.NDArray[np.intp],
                                                        npt.NDArray[np.float64]]:
    """Entries ``(rows, cols, data)`` grouped by row, stably: CSR ``(indptr, indices, data)``.

    A counting sort, O(n + nnz): scipy's COO-to-CSR kernel when it can be imported (3x
    cheaper than numpy's stable argsort of the rows on these sizes, measured: 0.24 against
    0.79 ms for 36 k entries), else the same result from a stable argsort.
    """
    indptr = np.empty(n + 1, dtype=np.intp)
    if _coo_tocsr is not None:
        rows = rows.astype(np.intp, copy=False)
        cols = cols.astype(np.intp, copy=False)
        indices = np.empty(len(rows), dtype=np.intp)
        out = np.empty(len(rows), dtype=np.float64)
        _coo_tocsr(n, n, len(rows), rows, cols, np.asarray(data, dtype=np.float64),
                   indptr, indices, out)
        return indptr, indices, out
    order = np.argsort(_sort_key(rows, n), kind='stable')
    indptr[0] = 0
    np.cumsum(np.bincount(rows, minlength=n), out=indptr[1:])
    return indptr, cols[order], data[order]


def concat_ranges(first: npt.NDArray[np.intp],
                  lengths: npt.NDArray[np.intp]) -> npt.NDArray[np.intp]:
    """The index ranges ``first[k] .. first[k] + lengths[k] - 1``, concatenated in order."""
    return np.repeat(first - np.cumsum(lengths) + lengths, lengths) + np.arange(int(lengths.sum()))


def _sort_key(values: npt.NDArray[np.integer], n: int) -> npt.NDArray[np.integer]:
    """Keys for a stable argsort: 16-bit when possible (then numpy uses a radix sort, 5x
    faster than on 64-bit keys)."""
    return values.astype(np.uint16) if n <= np.iinfo(np.uint16).max else values


def density_mask(neighbours: Neighbours, eta: int) -> npt.NDArray[np.bool_]:
    """Eq. 3: ρ(x) is true when x has at least η_L neighbours within δ_L."""
    return neighbours.degree() >= eta


def expand_bands(graph: Neighbours, dense: npt.NDArray[np.bool_],
                 seeds: npt.NDArray[np.intp], delta: float, *,
                 max_bands: int | None = None, points: npt.NDArray[np.float64] | None = None,
                 entity: npt.NDArray[np.intp] | None = None, bridge_gap: float = 0.0,
                 bridges: list[tuple[int, int]] | None = None) -> npt.NDArray[np.intp]:
    """Grow narrow bands from the zero level set ``seeds`` (Eqs. 1-4).

    Parameters
    ----------
    graph : neighbour pairs within δ_L.
    dense : (N,) density constraint ρ per point (Eq. 3).
    seeds : indices of L_0^0 (one or more points; one per entity is fine: entities are
        disconnected in ``graph``).
    delta : δ_L, metres.
    max_bands : stop after this many bands (used for the rough expansion of the root).
    points, entity, bridge_gap, bridges : when given, an entity whose parts are separated by
        an occlusion gap (no δ_L neighbours, but closer than ``bridge_gap``) is crossed: once
        the front dies, the unreached point of the entity closest to the banded ones seeds
        the next band, and the pair is appended to ``bridges`` for the graph.

    Returns
    -------
    (N,) band index per point: 0 for the seeds, k for the k-th narrow band, ``UNREACHED`` (-1)
    for points that no band reached (too sparse, or not connected to a seed).
    """
    n = graph.n
    if kernels.ENABLED:
        return _expand_compiled(graph, dense, seeds, delta, max_bands, points, entity,
                                bridge_gap, bridges)
    # One slot past the points: the padding index of ``graph.padded``, marked as banded.
    band_x = np.full(n + 1, UNREACHED, dtype=np.intp)
    band_x[n] = 0
    band = band_x[:n]
    seeds = np.asarray(seeds, dtype=np.intp)
    band[seeds] = 0
    dense_x = np.r_[dense, False]
    mark = np.zeros(n, dtype=bool)  # scratch: the new band
    close = np.zeros(n, dtype=bool)  # scratch: new points closer than ¾δ_L to the contour
    all_dense = bool(dense.all())
    curve = seeds
    rim = 0.75 * delta
    k = 0
    padded = graph.padded
    indptr, indices, data = graph.indptr, graph.indices, graph.data
    while max_bands is None or k < max_bands:
        new = near = np.zeros(0, dtype=np.intp)
        if curve.size:
            # Neighbours of the contour (Eq. 2 restricted to distances < δ_L), row by row.
            if padded is not None:
                cols, dist = padded[0][curve], padded[1][curve]
            else:
                offsets = concat_ranges(indptr[curve], indptr[curve + 1] - indptr[curve])
                cols, dist = indices[offsets], data[offsets]
            ok = band_x[cols] == UNREACHED  # (the padding counts as banded)
            if not all_dense:
                ok &= dense_x[cols]
            ok = np.flatnonzero(ok)  # (an index array gathers faster than the mask)
            cols, dist = cols.ravel()[ok], dist.ravel()[ok]
            # φ(x, t) < ¾δ_L for these: not on the next contour (Eq. 4).
            near = cols[dist < rim]
            mark[cols] = True
            new = np.flatnonzero(mark)
            mark[new] = False
        if new.size == 0:
            curve, k = _restart(graph, band, dense, k, points, entity, bridge_gap, bridges)
            if curve.size == 0:
                break
            continue
        k += 1
        band[new] = k  # Eq. 1: L_{t+1}, and L^0_{t+1} = L^0_t ∪ L_{t+1}
        close[near] = True
        outer = new[~close[new]]  # Eq. 4: the next contour, φ in [¾δ_L, δ_L)
        close[near] = False
        curve = outer if outer.size else new
    return band


def _expand_compiled(graph: Neighbours, dense: npt.NDArray[np.bool_],
                     seeds: npt.NDArray[np.intp], delta: float, max_bands: int | None,
                     points: npt.NDArray[np.float64] | None, entity: npt.NDArray[np.intp] | None,
                     bridge_gap: float, bridges: list[tuple[int, int]] | None
                     ) -> npt.NDArray[np.intp]:
    """:func:`expand_bands` with its band loop compiled (:func:`.kernels.grow_bands`): the
    same bands, a tenth of the cost (the numpy loop costs a dozen array operations a band)."""
    n = graph.n
    band = np.full(n, UNREACHED, dtype=np.intp)
    seeds = np.asarray(seeds, dtype=np.intp)
    band[seeds] = 0
    dense = np.ascontiguousarray(dense, dtype=bool)
    scratch = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    new, contour = np.empty(n, dtype=np.intp), np.empty(max(n, len(seeds)), dtype=np.intp)
    limit = np.iinfo(np.int64).max if max_bands is None else max_bands
    indptr = graph.indptr.astype(np.intp, copy=False)
    indices = graph.indices.astype(np.intp, copy=False)
    data = graph.data.astype(np.float64, copy=False)
    curve, k = seeds, 0
    while True:
        k = kernels.grow_bands(indptr, indices, data, dense, band, curve, 0.75 * delta, k, limit,
                               *scratch, new, contour)
        if k >= limit:
            return band
        curve, k = _restart(graph, band, dense, k, points, entity, bridge_gap, bridges)
        if curve.size == 0:
            return band


def _restart(graph: Neighbours, band: npt.NDArray[np.intp], dense: npt.NDArray[np.bool_],
             k: int, points: npt.NDArray[np.float64] | None,
             entity: npt.NDArray[np.intp] | None, bridge_gap: float,
             bridges: list[tuple[int, int]] | None) -> tuple[npt.NDArray[np.intp], int]:
    """Where the bands go on once their front died after band ``k``: the :func:`_leaks`, or
    else a seed across an occlusion gap (:func:`_bridge`, band ``k + 1``). Returns the new
    contour (empty: the expansion ends) and the last band's number."""
    curve = _leaks(graph, band, dense)
    if curve.size == 0 and bridge_gap > 0 and points is not None and entity is not None:
        curve = _bridge(points, band, dense, entity, bridge_gap, k + 1, bridges)
        if curve.size:
            k += 1
    return curve, k


def _bridge(points: npt.NDArray[np.float64], band: npt.NDArray[np.intp],
            dense: npt.NDArray[np.bool_], entity: npt.NDArray[np.intp], gap: float,
            next_band: int, bridges: list[tuple[int, int]] | None) -> npt.NDArray[np.intp]:
    """Seed the next band across an occlusion gap: the unreached dense point of an entity
    closest to that entity's banded points (within ``gap``). Returns the seed (or nothing)."""
    todo = np.flatnonzero(dense & (band == UNREACHED) & (entity >= 0))
    done = np.flatnonzero(band != UNREACHED)
    if todo.size == 0 or done.size == 0:
        return np.zeros(0, dtype=np.intp)
    dist, near = cKDTree(points[done]).query(points[todo], distance_upper_bound=gap)
    same = np.isfinite(dist)
    same[same] = entity[done[near[same]]] == entity[todo[same]]
    if not same.any():
        return np.zeros(0, dtype=np.intp)
    best = int(np.argmin(np.where(same, dist, np.inf)))
    seed, anchor = int(todo[best]), int(done[near[best]])
    band[seed] = next_band
    if bridges is not None:
        bridges.append((anchor, seed))
    return np.array([seed], dtype=np.intp)


def _leaks(graph: Neighbours, band: npt.NDArray[np.intp],
           dense: npt.NDArray[np.bool_]) -> npt.NDArray[np.intp]:
    """Banded points that still border unreached dense points.

    Eq. 4 moves the contour to the outer rim of each band, so a limb that joins a band away
    from its rim (a chair leg under the seat's edge) is never within δ_L of a contour. When
    the front dies out, these border points become the contour and the expansion goes on, so
    such parts are organised into bands instead of being lost.
    """
    i, j = graph.i, graph.j
    bi, bj = band[i] != UNREACHED, band[j] != UNREACHED
    fwd = bi & ~bj & dense[j]
    bwd = bj & ~bi & dense[i]
    return np.unique(np.concatenate([i[fwd], j[bwd]]))


def split_subbands(points: npt.NDArray[np.float64], graph: Neighbours,
                   band: npt.NDArray[np.intp], *, connect: float, max_points: int,
                   min_points: int = 1) -> npt.NDArray[np.intp]:
    """Label sub-bands: connected pieces of each band (at distance ``connect``), capped in size.

    Pieces smaller than ``min_points`` (slivers left where a band wraps around a surface
    fold) are merged into the adjacent sub-band they share most neighbour pairs with: they
    could never be attached (Section 4.2 needs P points per side) and would otherwise become
    spurious graph leaves.

    Returns (N,) sub-band labels 0..S-1 (-1 for unreached points).
    """
    n = len(points)
    sub = np.full(n, UNREACHED, dtype=np.intp)
    reached = np.flatnonzero(band != UNREACHED)
    if reached.size == 0:
        return sub
    bi, bj = band[graph.i], band[graph.j]
    comp = graph.components((bi == bj) & (bi != UNREACHED) & (graph.d < connect))
    comp_r = comp[reached]
    # Renumber components by (band, component) so labels are ordered by band.
    order = np.lexsort((comp_r, band[reached]))
    comp_sorted = comp_r[order]
    first = np.r_[True, comp_sorted[1:] != comp_sorted[:-1]]
    labels = np.cumsum(first) - 1
    sub[reached[order]] = labels
    counts = np.bincount(labels)
    if min_points > 1:
        sub = _merge_small(graph, sub, counts, min_points, connect)
        counts = np.bincount(sub[reached])
    big = np.flatnonzero(counts > max_points)
    if big.size:
        sub = _cap_subbands(points, sub, big, counts, max_points)
    return sub


def _merge_small(graph: Neighbours, sub: npt.NDArray[np.intp], counts: npt.NDArray[np.intp],
                 min_points: int, connect: float) -> npt.NDArray[np.intp]:
    """Relabel each sub-band below ``min_points`` as its best-connected larger neighbour."""
    small = counts < min_points
    if not small.any():
        return sub
    si, sj = sub[graph.i], sub[graph.j]
    smallx = np.r_[small, False]  # index -1 (unreached) -> not small
    close = graph.d < connect
    small_i, small_j = smallx[si], smallx[sj]
    fwd = small_i & ~small_j & (sj != UNREACHED) & close
    bwd = small_j & ~small_i & (si != UNREACHED) & close
    a = np.concatenate([si[fwd], sj[bwd]])
    b = np.concatenate([sj[fwd], si[bwd]])
    if a.size == 0:
        return sub
    s = counts.size
    key, cnt = np.unique(a.astype(np.int64) * s + b, return_counts=True)
    src, dst = key // s, key % s
    order = np.lexsort((-cnt, src))
    first = np.r_[True, src[order][1:] != src[order][:-1]]
    remap = np.arange(s)
    remap[src[order][first]] = dst[order][first]
    remap = np.r_[remap, UNREACHED]  # index -1 (unreached) stays unreached
    used = np.zeros(s, dtype=bool)
    used[remap[:-1]] = True
    compact = np.r_[np.cumsum(used) - 1, UNREACHED]  # labels stay 0..S'-1, in order
    return compact[remap[sub]]


def _cap_subbands(points: npt.NDArray[np.float64], sub: npt.NDArray[np.intp],
                  big: npt.NDArray[np.intp], counts: npt.NDArray[np.intp],
                  max_points: int) -> npt.NDArray[np.intp]:
    """Cut each oversized sub-band into ceil(n / max_points) slices along its main axis; the
    new slices get the labels after ``counts.size - 1``, in the order of ``big`` (ascending).

    All oversized sub-bands at once: per-label means and covariances by bincount, one batched
    eigendecomposition, one sort by (label, position along the axis).
    """
    s = counts.size
    oversized = np.zeros(s + 1, dtype=bool)  # slot -1: unreached points
    oversized[big] = True
    members = np.flatnonzero(oversized[sub])
    label = sub[members]
    cols = [points[members, a] for a in range(3)]
    size = np.maximum(counts, 1)
    rel = [c - (np.bincount(label, weights=c, minlength=s) / size)[label] for c in cols]
    cov = np.empty((len(big), 3, 3))
    for a in range(3):
        for b in range(a, 3):
            cov[:, a, b] = cov[:, b, a] = np.bincount(label, weights=rel[a] * rel[b],
                                                      minlength=s)[big]
    main_axis = np.zeros((s, 3))
    main_axis[big] = np.linalg.eigh(cov)[1][:, :, -1]  # largest-variance direction
    along = sum(r * main_axis[label, a] for a, r in enumerate(rel))
    order = np.lexsort((along, label))
    label = label[order]
    first = np.searchsorted(label, label)  # where each label's run starts
    pieces = -(-counts // max_points)
    slot = (np.arange(len(label)) - first) * pieces[label] // counts[label]
    # Slice 0 keeps the label (labels stay compact); slices 1.. of the k-th oversized
    # sub-band follow those of the sub-bands before it.
    base = np.zeros(s, dtype=np.intp)
    base[big] = s + np.r_[0, np.cumsum(pieces[big] - 1)[:-1]] - 1
    out = sub.copy()
    out[members[order]] = np.where(slot == 0, label, base[label] + slot)
    return out
