"""Section 4.2: topology graph over sub-bands, geodesic distances and end-effector search.

- Nodes are sub-band centroids; an edge joins two sub-bands only when they are *attached*: each
  has at least P points closer than λ to the other. Edge weight is the centroid distance (Eq. 5).
- The geodesic distance of a node is the sum of the weights on its shortest path to the root
  (Eq. 6); the approximate geodesic goes through the mid-band of that path (Eq. 7).
- End-effectors are found by iterated Dijkstra (Baak et al.): the farthest node from the
  target set is an end-effector; its path is joined to the target set by zero-weight edges
  (equivalently, all of its nodes become sources), and the search repeats until the farthest
  node is closer than g, or, between ``chain_geodesic`` and g, no extreme ends a chain (see
  :func:`find_end_effectors`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from .bands import UNREACHED, Neighbours, symmetric_csr

if TYPE_CHECKING:
    import numpy.typing as npt


@dataclass(frozen=True)
class TopologyGraph:
    """Sub-band graph of the whole frame (entities are disconnected components).

    ``centroids`` (K, 3) node positions; ``sizes`` (K,) points per node; ``band`` (K,) band
    of each node; ``dense_weights`` (K, K) symmetric Eq. 5 weights, 0 where there is no edge
    (``weights`` gives them as a sparse matrix). ``dist`` (K, K) and
    ``pred`` (K, K) are all-pairs geodesic distances (Eq. 6) and predecessors: the graph has
    a few hundred nodes at most, so one all-pairs Dijkstra per frame is cheaper than the many
    single-source runs the iterated search and the tracker would otherwise make.
    """

    centroids: npt.NDArray[np.float64]
    sizes: npt.NDArray[np.intp]
    band: npt.NDArray[np.intp]
    dense_weights: npt.NDArray[np.float64]
    dist: npt.NDArray[np.float64]
    pred: npt.NDArray[np.intp]

    @property
    def n_nodes(self) -> int:
        return len(self.centroids)

    @property
    def weights(self) -> sparse.csr_matrix:
        """Eq. 5 edge weights as a sparse symmetric (K, K) matrix."""
        return sparse.csr_matrix(self.dense_weights)

    def shortest_paths(self, sources: npt.ArrayLike) -> tuple[npt.NDArray[np.float64],
                                                              npt.NDArray[np.intp]]:
        """Geodesic distance (Eq. 6) of every node to the nearest of ``sources`` and the
        predecessor array towards it (-9999 at sources and unreachable nodes)."""
        src = np.atleast_1d(np.asarray(sources, dtype=np.intp))
        d = self.dist[src]
        nearest = np.argmin(d, axis=0)
        cols = np.arange(self.n_nodes)
        return d[nearest, cols], self.pred[src[nearest], cols]

    def geodesic_between(self, a: npt.ArrayLike, b: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """(len(a), len(b)) geodesic distances between nodes ``a`` and nodes ``b`` (inf if
        they are in different components)."""
        a = np.atleast_1d(np.asarray(a, dtype=np.intp))
        b = np.atleast_1d(np.asarray(b, dtype=np.intp))
        return self.dist[np.ix_(a, b)]


def build_graph(points: npt.NDArray[np.float64], subband: npt.NDArray[np.intp],
                band: npt.NDArray[np.intp], neighbours: Neighbours, *,
                attach_distance: float, attach_points: int,
                bridges: list[tuple[int, int]] = ()) -> TopologyGraph:
    """Build the sub-band graph with attachment edges and Eq. 5 weights.

    ``neighbours`` is a radius graph of the points whose radius is at least λ
    (``attach_distance``); sub-band ``i`` and ``j`` are attached when at least P
    (``attach_points``) points of ``i`` have a point of ``j`` within λ, and vice versa.
    ``bridges`` are point pairs across occlusion gaps found by the band expansion: their
    sub-bands are linked too (an occluder separated them, not the entity's topology).
    """
    reached = subband != UNREACHED
    k = int(subband.max()) + 1 if reached.any() else 0
    sizes = np.bincount(subband[reached], minlength=k)
    centroids = np.zeros((k, 3))
    for axis in range(3):
        centroids[:, axis] = np.bincount(subband[reached], weights=points[reached, axis],
                                         minlength=k)
    centroids /= np.maximum(sizes, 1)[:, None]
    node_band = np.full(k, UNREACHED, dtype=np.intp)
    node_band[subband[reached]] = band[reached]

    all_si, all_sj = subband[neighbours.i], subband[neighbours.j]
    near = np.flatnonzero(neighbours.d < attach_distance)  # indices gather faster than masks
    pi, pj = neighbours.i[near], neighbours.j[near]
    si, sj = all_si[near], all_sj[near]
    cross = np.flatnonzero((si != sj) & (si != UNREACHED) & (sj != UNREACHED))
    pi, pj, si, sj = pi[cross], pj[cross], si[cross], sj[cross]
    # touch[p * k + b]: point p has a point of sub-band b within λ (both directions of
    # each pair).
    touch = np.zeros(len(points) * k, dtype=bool)
    touch[pi * k + sj] = True
    touch[pj * k + si] = True
    p, b = np.divmod(np.flatnonzero(touch), k)
    counts = np.bincount(subband[p] * k + b, minlength=k * k).reshape(k, k)
    attached = np.minimum(counts, counts.T) >= attach_points
    if len(bridges):
        pairs = np.asarray(bridges, dtype=np.intp)
        sa, sb = subband[pairs[:, 0]], subband[pairs[:, 1]]
        ok = (sa != sb) & (sa != UNREACHED) & (sb != UNREACHED)
        attached[sa[ok], sb[ok]] = attached[sb[ok], sa[ok]] = True
    dense, dist, pred = _weigh(attached, centroids)
    if _join_pieces(attached, centroids, all_si, all_sj, dist):
        dense, dist, pred = _weigh(attached, centroids)
    return TopologyGraph(centroids, sizes, node_band, dense, dist, pred)


def _weigh(attached: npt.NDArray[np.bool_], centroids: npt.NDArray[np.float64],
           ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.intp]]:
    """Eq. 5 weights of the ``attached`` node pairs as a dense symmetric matrix, and the
    all-pairs geodesic distances (Eq. 6) and predecessors over them."""
    k = len(attached)
    rows, cols = np.nonzero(np.triu(attached, k=1))
    seg = centroids[rows] - centroids[cols]
    w = np.maximum(np.sqrt(np.einsum('ij,ij->i', seg, seg)), 1e-9)  # Eq. 5
    dense = np.zeros((k, k))
    dense[rows, cols] = dense[cols, rows] = w
    # Both directions as a sparse matrix, searched as a directed graph: 3x cheaper than
    # handing csgraph the dense matrix (which it converts) or asking it to symmetrise.
    indptr, indices, data = symmetric_csr(k, rows, cols, w)
    both = sparse.csr_matrix((data, indices, indptr), shape=(k, k))
    dist, pred = csgraph.dijkstra(both, directed=True, return_predecessors=True)
    return dense, dist, pred


def _join_pieces(attached: npt.NDArray[np.bool_], centroids: npt.NDArray[np.float64],
                 si: npt.NDArray[np.intp], sj: npt.NDArray[np.intp],
                 dist: npt.NDArray[np.float64]) -> bool:
    """Join graph pieces that attachment left apart but the band expansion connected.

    Attachment asks for P points within λ on both sides; the expansion crosses wherever one
    point is within δ_L. A chain it reached through fewer contact points (a forearm pointing
    at the camera, seen only around its edge; a chair leg meeting the seat in a few points)
    would be cut off from the root, and its end-effectors lost. Each such piece is linked to
    the rest by its shortest link (Eq. 5 weight) among sub-band pairs with neighbouring points
    (``si``, ``sj``: sub-bands of the two points of every neighbour pair), smallest first
    (Kruskal over pieces), so pieces are joined exactly once and attached ones are unchanged.
    The pieces are read off the geodesic distances ``dist`` over ``attached`` (a node's piece
    is the lowest node it reaches), so a frame with nothing to join costs no extra pass.
    Modifies ``attached`` in place; returns whether it added any link.
    """
    k = len(attached)
    if k < 2:
        return False
    piece = np.argmax(np.isfinite(dist), axis=1)  # the lowest reachable node (itself at worst)
    ok = (si != UNREACHED) & (sj != UNREACHED)
    a, b = si[ok], sj[ok]
    cross = piece[a] != piece[b]
    if not cross.any():
        return False
    parent = piece.tolist()  # union-find over sub-bands, one tree per piece to start with

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    links = np.unique(np.minimum(a[cross], b[cross]) * k + np.maximum(a[cross], b[cross]))
    a, b = links // k, links % k
    length = np.linalg.norm(centroids[a] - centroids[b], axis=1)
    for m in np.argsort(length, kind='stable'):  # few links: one per piece boundary
        ra, rb = find(int(a[m])), find(int(b[m]))
        if ra != rb:
            parent[ra] = rb
            attached[a[m], b[m]] = attached[b[m], a[m]] = True
    return True


def path_to_sources(pred: npt.NDArray[np.intp], node: int) -> npt.NDArray[np.intp]:
    """Nodes from ``node`` back to its source along a predecessor array (inclusive)."""
    path = [node]
    while pred[path[-1]] >= 0:
        path.append(int(pred[path[-1]]))
    return np.array(path, dtype=np.intp)


def find_end_effectors(graph: TopologyGraph, root: int, *, min_geodesic: float,
                       max_count: int, chain_geodesic: float | None = None,
                       chain_subbands: int = 3, chain_min_points: int = 1,
                       loop_sides: list[bool] | None = None, scale_length: float = 0.0,
                       scale_min: float = 1.0, tip_depth: float = 0.0,
                       min_tip_points: int = 0, extremes: list[int] | None = None,
                       floor_geodesic: float = 0.0, verdicts: list[bool] | None = None,
                       ) -> list[tuple[int, npt.NDArray[np.intp], float]]:
    """Iterated Dijkstra with zero-weight edges along each found path (Baak et al.).

    Returns ``(node, path, protrusion)`` per end-effector in the order found: ``path`` runs
    from the end-effector to the root over the original graph (for Eqs. 6-7); ``protrusion``
    is its geodesic distance to the target set when found (root and earlier paths), the
    quantity compared with g (``min_geodesic``).

    Chains below g: an extreme whose protrusion lies in [``chain_geodesic``, g) is still an
    end-effector when it ends a chain: its path to the target set crosses at least
    ``chain_subbands`` sub-bands (edges; the extreme counts, the target node does not), its
    sub-band holds at least ``chain_min_points`` points (a sliver below the sub-band minimum
    is no part: a chair seat's rim seen edge-on in the unit tests), and it is a local maximum
    of the geodesic distance to the root (Eq. 6), as the paper defines an end-effector. The
    band expansion lays a band every δ_L or less along a limb, so a real protrusion of
    0.2-0.3 m crosses about 3 or more sub-bands; most near-g extremes that are no end-effectors
    are the far side of one or two long edges (a large sub-band sliced on a broad surface, a
    joining link: median edge 0.13 m against 0.09 m for true ones) or a point between two
    found paths that is no farther from the root than a neighbour. The farthest chain end is
    taken; extremes passed over do not become targets. Why: a T-pose head protrudes only
    ~0.29 m from the paths of the hands, which cross the shoulders, and arms raised over the
    head do the same. The evidence for the rule (how many true and false extremes below g
    end chains) is in docs/design.md.
    ``chain_geodesic`` None or >= g: g alone, as the paper.

    ``loop_sides``: a list that receives, per end-effector returned, whether it is the far
    side of a loop (:func:`_loop_far_side`); None: not asked.

    Slivers: with ``min_tip_points`` > 0, an extreme whose terminal part (the sub-bands on
    its path within ``tip_depth``) holds fewer points is a sliver, and the end-effector is
    the first node back along its path whose terminal part holds as many
    (:func:`_solid_tip`); the extreme still decides g, loops and the zero-weight path.
    ``extremes``: a list that receives, per end-effector returned, its extreme (the node
    itself unless a sliver moved it); None: not asked.

    Over-generation (for the candidate scorer, :mod:`.candidates`): with ``floor_geodesic``
    > 0 the iteration goes on where the thresholds above stop it, taking the farthest node
    as long as it protrudes ``floor_geodesic`` or more, and ``verdicts`` (a list) receives
    per end-effector returned whether the thresholds alone would have returned it (found
    before they stopped the iteration). Those found first are the same either way.

    Relative thresholds: once the first (farthest) end is found, its geodesic distance L
    measures the entity; below ``scale_length`` g and the chain threshold shrink by
    L / ``scale_length``, to ``scale_min`` of their values at least. Why: g in metres suits one
    body size. A standing adult's farthest end lies 1.0-1.4 m from the root (the 1.58 and
    1.75 m models) and keeps g; a 1.2 m child's head lies about 0.25 m from the root and,
    once the path to a hand hanging at its side (crossing the shoulder) is found, protrudes
    about 0.16 m: in a dev clip of such a child, whose farthest end lies within 0.9 m of the
    root in 80 of its 137 frames, the single-frame estimator finds the head in 43 frames
    instead of 24. The floor keeps a body cut by the view (an upper body close to the
    camera: a short first end for reasons other than size) from finding ends on every bump.
    docs/design.md has the measurements.
    """
    pred_root = graph.pred[root]
    low = min_geodesic if chain_geodesic is None else min(chain_geodesic, min_geodesic)
    sources = [root]
    found: list[tuple[int, npt.NDArray[np.intp], float]] = []
    stopped = False  # the thresholds would have ended the iteration
    while len(found) < max_count:
        dist, pred = graph.shortest_paths(sources)
        dist = np.where(np.isfinite(dist), dist, -1.0)
        node = int(np.argmax(dist))
        if not stopped and dist[node] < low:
            stopped = True
        elif not stopped and dist[node] < min_geodesic:
            chain = _farthest_chain(graph, root, dist, pred, low, chain_subbands,
                                    chain_min_points)
            stopped = chain < 0
            node = node if stopped else chain
        if stopped and (floor_geodesic <= 0 or dist[node] < floor_geodesic):
            break
        if verdicts is not None:
            verdicts.append(not stopped)
        extreme = node
        if min_tip_points > 0:
            node = _solid_tip(graph, extreme, dist, pred, tip_depth, min_tip_points)
        found.append((node, path_to_sources(pred_root, node), float(dist[extreme])))
        if extremes is not None:
            extremes.append(extreme)
        if len(found) == 1 and scale_length > 0:
            shrink = min(1.0, max(scale_min, float(dist[extreme]) / scale_length))
            min_geodesic, low = min_geodesic * shrink, low * shrink
        if loop_sides is not None:
            loop_sides.append(len(sources) > 1
                              and _loop_far_side(graph, extreme, dist, pred, min_geodesic))
        # Zero-weight edges from every node of the new path to the target: add them as sources.
        sources.extend(path_to_sources(pred, extreme)[:-1].tolist())
    return found


def _solid_tip(graph: TopologyGraph, extreme: int, dist: npt.NDArray[np.float64],
               pred: npt.NDArray[np.intp], depth: float, min_points: int) -> int:
    """The end-effector's node for ``extreme`` (``dist``, ``pred``: distances and
    predecessors towards the target set): the extreme when the sub-bands on its path within
    ``depth`` of it hold at least ``min_points`` points, else the first node back along the
    path whose own such stretch does; the extreme again when that would reach the target set
    (an end on an earlier path or at the root; nor do the target set's nodes count in a
    stretch: a branch of slivers off the root is no part next to the root).

    Why: a surface seen edge-on breaks into sub-bands of one or two points, and a path can
    run on through them past the part it leaves: a foot seen from the side, behind a table,
    whose path continued up through a few points of the far leg and put the end 0.2 m up
    the shin. A part's end holds a few points within ``tip_depth`` even where its outermost
    sub-band is below the sub-band minimum (a hand's often is: asking each sub-band for the
    minimum moved hands up the forearm, docs/results.md)."""
    tip = extreme
    while True:
        # The nodes of the stretch, the target set's excluded (they are other paths' parts).
        points, node = 0, tip
        while node >= 0 and pred[node] >= 0 and dist[tip] - dist[node] <= depth:
            points += int(graph.sizes[node])
            node = int(pred[node])
        if points >= min_points:
            return tip
        nxt = int(pred[tip])
        if nxt < 0 or pred[nxt] < 0:  # the target set is next (or reached)
            return extreme
        tip = nxt


def _loop_far_side(graph: TopologyGraph, node: int, dist: npt.NDArray[np.float64],
                   pred: npt.NDArray[np.intp], min_loop: float) -> bool:
    """Whether the extreme ``node`` is the far side of a loop that a found path runs through
    (``dist``, ``pred``: distances and predecessors towards the target set, the root and the
    paths found before): two of its neighbours nearer the targets reach them by disjoint
    paths, at target nodes at least ``min_loop`` apart (geodesic, Eq. 6).

    A limb that touches the body closes a loop (arms folded, hands clasped in front of the
    chest, a hand on the hip). The first path found runs through the loop's farthest point
    and down one of its sides; the other side then hangs between two points of that path,
    and its farthest point from them (the elbow) is an extreme of the next iteration, often
    g or more from the paths: an end-effector of the iterated Dijkstra that ends no chain. A
    real chain (a limb, a head) is one sub-band per band, so its neighbours' paths join at
    once and reach the targets at one point."""
    neighbours = np.flatnonzero(graph.dense_weights[node] > 0)
    down = neighbours[dist[neighbours] < dist[node]]
    paths = [path_to_sources(pred, int(n)) for n in down]  # a loop over neighbours only
    for i, path in enumerate(paths):
        for other in paths[i + 1:]:
            if (not np.isin(path, other).any()
                    and graph.dist[path[-1], other[-1]] >= min_loop):
                return True
    return False


def _farthest_chain(graph: TopologyGraph, root: int, dist: npt.NDArray[np.float64],
                    pred: npt.NDArray[np.intp], low: float, subbands: int,
                    min_points: int) -> int:
    """The farthest node with ``dist`` (to the target set) >= ``low`` that is a chain end:
    its path to the target set (along ``pred``) has at least ``subbands`` edges, it holds at
    least ``min_points`` points (no sliver), and it is a local maximum of the geodesic
    distance to the root (Eq. 6), as an end-effector is, not a point between two found paths.
    -1 if there is none. Hop counts of all nodes at once:
    ``subbands`` steps up the predecessor array."""
    hops = np.zeros(len(dist), dtype=np.intp)
    up = np.arange(len(dist))
    for _ in range(subbands):
        alive = up >= 0
        up[alive] = pred[up[alive]]
        hops += up >= 0
    from_root = graph.dist[root]
    beside = np.where(graph.dense_weights > 0, from_root[None, :], -np.inf).max(axis=1)
    ok = np.flatnonzero((dist >= low) & (hops >= subbands) & (from_root >= beside)
                        & (graph.sizes >= min_points))
    return int(ok[np.argmax(dist[ok])]) if ok.size else -1


def geodesic(graph: TopologyGraph, path: npt.NDArray[np.intp]) -> float:
    """Eq. 6: the sum of edge weights along ``path``."""
    seg = graph.centroids[path[1:]] - graph.centroids[path[:-1]]
    return float(np.linalg.norm(seg, axis=1).sum())


def approximate_geodesic(position: npt.NDArray[np.float64], graph: TopologyGraph,
                         path: npt.NDArray[np.intp], root: npt.NDArray[np.float64]) -> float:
    """Eq. 7: dist_E(e, mid) + dist_E(mid, L_0^0), ``mid`` the mid-band of the shortest path.

    The mid-band is the node halfway along the path (by node count); it makes the distance
    robust to occlusions that lengthen the full path (Fig. 3a).
    """
    return approximate_geodesic_along(position, graph.centroids[path], root)


def approximate_geodesic_along(position: npt.NDArray[np.float64],
                               path_points: npt.NDArray[np.float64],
                               root: npt.NDArray[np.float64]) -> float:
    """Eq. 7 through a path given by its node positions (end-effector first), e.g. the path
    a track kept from the frame it was last detected in."""
    mid = path_points[len(path_points) // 2]
    return float(np.linalg.norm(position - mid) + np.linalg.norm(mid - root))


def distance_to_path(position: npt.NDArray[np.float64],
                     path_points: npt.NDArray[np.float64]) -> float:
    """Euclidean distance from ``position`` to the polyline through ``path_points`` (K, 3), a
    path by its node positions; inf for an empty path."""
    pts = np.asarray(path_points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return float('inf')
    if len(pts) == 1:
        return float(np.linalg.norm(position - pts[0]))
    start, step = pts[:-1], np.diff(pts, axis=0)
    t = np.clip(((position - start) * step).sum(axis=1)
                / np.maximum((step * step).sum(axis=1), 1e-12), 0.0, 1.0)
    return float(np.linalg.norm(start + t[:, None] * step - position, axis=1).min())
