"""The single-frame estimator of Section 4 (the R-NBLS-style baseline): frame in, candidates."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from .bands import (
    UNREACHED,
    Neighbours,
    concat_ranges,
    density_mask,
    expand_bands,
    split_subbands,
)
from .candidates import select_candidates
from .cloud import foreground_cloud
from .floor import FloorPlane
from .graph import TopologyGraph, approximate_geodesic, build_graph, find_end_effectors, geodesic
from .params import EndeffParams
from .readable import Edges, ReadableArea, fit_edges, strided_read
from .types import Candidate, Intrinsics, RGBDFrame

if TYPE_CHECKING:
    import numpy.typing as npt

    from .background import BackgroundModel
    from .candidates import Scored


@dataclass(frozen=True)
class EntityEstimate:
    """One connected foreground cluster with its root, topology graph and candidates."""

    entity: int
    root: npt.NDArray[np.float64]
    candidates: list[Candidate]
    graph: TopologyGraph
    point_index: npt.NDArray[np.intp]
    root_node: int = 0
    #: Extremes on the far side of a loop (``loop_far_sides``): no end-effectors, but a track
    #: already following one may match it.
    loop_sides: list[Candidate] = field(default_factory=list)


@dataclass(frozen=True)
class FrameEstimate:
    """Everything the Section 4 estimator found in one frame.

    ``points`` (N, 3) is the foreground after downsampling; ``band`` and ``subband`` label each
    point (-1 where the expansion never reached it), ``entity`` the cluster it belongs to (-1:
    too small). ``unreachable`` counts entity points that no band reached. ``cut`` (N,) marks
    the points beside a dropped table top (:attr:`.cloud.ForegroundCloud.cut`), or is None.
    """

    points: npt.NDArray[np.float64]
    band: npt.NDArray[np.intp]
    subband: npt.NDArray[np.intp]
    entity: npt.NDArray[np.intp]
    entities: list[EntityEstimate]
    unreachable: int
    graph: TopologyGraph | None = None
    floor: FloorPlane | None = None
    stage_ms: dict[str, float] = field(default_factory=dict)
    cut: npt.NDArray[np.bool_] | None = None
    #: With ``candidate_floor``: every over-generated candidate before the selection
    #: (:class:`.candidates.Scored`); None otherwise.
    scored: Scored | None = None

    def positions(self) -> npt.NDArray[np.float64]:
        """(M, 3) positions of all candidates of all entities."""
        rows = [c.position for e in self.entities for c in e.candidates]
        return np.array(rows, dtype=np.float64).reshape(-1, 3)


def estimate_frame(frame: RGBDFrame, params: EndeffParams | None = None, *,
                   floor: FloorPlane | None = None,
                   background: BackgroundModel | None = None,
                   readable: ReadableArea | None = None) -> FrameEstimate:
    """Run Sections 3-4 on one frame: foreground cloud, bands, graph, candidates.

    ``floor`` may give a known floor plane (the tracker passes the previous frame's);
    ``background`` a static-background model that learns from the frame and removes what
    never moved (:mod:`.background`); ``readable`` the stream's readable area
    (:mod:`.readable`), whose dead margins cut ends as the image border does (without it, the
    frame's own readings tell where the margins are).
    Raises :class:`~endeff_ros.core.errors.InputError` for unusable frames; an empty
    foreground is not an error (the estimate simply has no entities).
    """
    params = params or EndeffParams()
    timer = _StageTimer()
    cloud = foreground_cloud(frame.depth, frame.intrinsics, params, floor=floor,
                             background=background, stamp_ns=frame.stamp_ns,
                             color=frame.color)
    timer.lap('cloud')
    estimate = estimate_points(cloud.points, params, colors=cloud.colors, timer=timer)
    estimate = dataclasses.replace(estimate, floor=cloud.floor, cut=cloud.cut)
    if params.drop_cut_ends:
        edges = None
        if params.cut_dead_margins:
            edges = (readable.update(frame.depth, params.pixel_stride, params.cut_margin_px)
                     if readable is not None else
                     fit_edges(strided_read(frame.depth, params.pixel_stride),
                               params.pixel_stride, params.cut_margin_px))
        estimate = drop_cut_ends(estimate, frame.intrinsics, params, edges)
    if params.candidate_floor > 0:
        estimate = select_candidates(estimate, frame.intrinsics, params)
    return estimate


def cut_nodes(points: npt.NDArray[np.float64], subband: npt.NDArray[np.intp],
              intrinsics: Intrinsics, params: EndeffParams,
              cut: npt.NDArray[np.bool_] | None = None,
              edges: Edges | None = None) -> npt.NDArray[np.intp]:
    """Sub-bands (graph nodes) cut by the view or by the foreground box: those with a point
    projecting within ``cut_margin_px`` of the image border, or lying within one voxel of a
    face of the box, or marked in ``cut`` (N,) (beside a dropped table top:
    :attr:`~.cloud.ForegroundCloud.cut`). A body that leaves the image (or the box, or goes
    behind a table) ends there, so its farthest sub-band is an extreme of the graph although
    it is no end of the body. ``edges``: the readable area's edges (dead margins of registered
    depth, :mod:`.readable`), which count as the image border."""
    z = np.maximum(points[:, 2], 1e-6)
    u = intrinsics.fx * points[:, 0] / z + intrinsics.cx
    v = intrinsics.fy * points[:, 1] / z + intrinsics.cy
    m = params.cut_margin_px
    near = ((u < m) | (u > intrinsics.width - 1 - m) | (v < m)
            | (v > intrinsics.height - 1 - m))
    if edges is not None:
        near |= edges.near(u, v, m)
    s = max(params.voxel_size, 0.01)
    for k, axis in enumerate('xyz'):
        lo, hi = getattr(params, f'box_min_{axis}'), getattr(params, f'box_max_{axis}')
        near |= (points[:, k] < lo + s) | (points[:, k] > hi - s)
    if cut is not None:
        near |= cut
    return np.unique(subband[near & (subband >= 0)])


def drop_cut_ends(estimate: FrameEstimate, intrinsics: Intrinsics,
                  params: EndeffParams, edges: Edges | None = None) -> FrameEstimate:
    """``estimate`` without the candidates whose sub-band is cut (:func:`cut_nodes`, with
    the points its ``cut`` marks and the readable area's ``edges``); when candidates are
    over-generated (``candidate_floor``) they are marked ``cut`` instead, for the scorer."""
    cut = cut_nodes(estimate.points, estimate.subband, intrinsics, params, estimate.cut,
                    edges)
    if not cut.size or not any(e.candidates for e in estimate.entities):
        return estimate
    def is_cut(c: Candidate) -> bool:  # its node, or the sliver it was moved back from
        return bool(np.isin([c.node, c.node if c.extreme is None else c.extreme], cut).any())

    if params.candidate_floor > 0:
        entities = [dataclasses.replace(e, candidates=[
            dataclasses.replace(c, cut=True, thresholds=False) if is_cut(c) else c
            for c in e.candidates]) for e in estimate.entities]
        return dataclasses.replace(estimate, entities=entities)
    entities = [dataclasses.replace(e, candidates=[c for c in e.candidates if not is_cut(c)])
                for e in estimate.entities]
    return dataclasses.replace(estimate, entities=entities)


def estimate_points(points: npt.NDArray[np.float64], params: EndeffParams | None = None, *,
                    colors: npt.NDArray[np.float64] | None = None,
                    timer: _StageTimer | None = None) -> FrameEstimate:
    """Section 4 on a foreground cloud (N, 3), metres, optical frame; ``colors`` (N, 3),
    the points' 0-255 RGB, for ``color_edge_rgb``.

    Density (Eq. 3) and entities, the root (refined centroid of the first N bands), narrow
    bands (Eqs. 1-4), sub-bands, the attachment graph (Eq. 5) and its all-pairs geodesics
    (Eq. 6), then per entity the iterated Dijkstra's end-effectors with their Eq. 6 and Eq. 7
    distances. Usable without any image (clouds from any source).
    """
    params = params or EndeffParams()
    timer = timer or _StageTimer()
    neighbours = Neighbours.build(points, max(params.band_delta, params.attach_distance),
                                  steep_ratio=params.steep_step_ratio,
                                  steep_min=params.steep_step_min, colors=colors,
                                  color_rgb=params.color_edge_rgb,
                                  color_step=params.color_edge_step)
    within = (neighbours.within(params.band_delta)
              if params.attach_distance > params.band_delta else neighbours)
    dense = density_mask(within, params.band_eta)
    entity = _entities(points, within, dense, params.min_entity_points, params.entity_gap)
    timer.lap('neighbours')

    seeds = _roots(points, within, dense, entity, params)
    bridges: list[tuple[int, int]] = []
    band = expand_bands(within, dense, seeds, params.band_delta, points=points, entity=entity,
                        bridge_gap=params.entity_gap, bridges=bridges)
    band[seeds] = 1  # L_0^0 joins the first band so the root node has the first band's size
    band[entity < 0] = UNREACHED
    timer.lap('bands')
    subband = split_subbands(points, neighbours, band, connect=params.band_delta,
                             max_points=params.subband_max_points,
                             min_points=params.subband_min_points)
    timer.lap('subbands')
    graph = build_graph(points, subband, band, neighbours,
                        attach_distance=params.attach_distance,
                        attach_points=params.attach_points, bridges=bridges)
    timer.lap('graph')

    found = []  # (entity, node, path, protrusion) of every end-effector in the frame
    # Per found extreme: on the far side of a loop (asked only with loop_far_sides).
    sides: list[bool] | None = [] if params.loop_far_sides else None
    extremes: list[int] = []  # per end-effector, its extreme (the node unless a sliver)
    verdicts: list[bool] = []  # per end-effector, whether g and the chain rule return it
    orders: list[int] = []  # per end-effector, its rank in its entity
    for e, seed in enumerate(seeds):
        before = len(found)
        root_node = int(subband[seed])
        found += [(e, *f) for f in find_end_effectors(graph, root_node,
                                                       min_geodesic=params.min_geodesic,
                                                       chain_geodesic=params.chain_geodesic,
                                                       chain_subbands=params.chain_subbands,
                                                       chain_min_points=params.subband_min_points,
                                                       max_count=params.max_end_effectors,
                                                       loop_sides=sides,
                                                       scale_length=params.scale_length,
                                                       scale_min=params.scale_min,
                                                       tip_depth=params.tip_depth,
                                                       min_tip_points=params.min_tip_points,
                                                       extremes=extremes,
                                                       floor_geodesic=params.candidate_floor,
                                                       verdicts=verdicts)]
        orders += range(len(found) - before)
    dist_root = [graph.dist[subband[seeds[e]], path] for e, _, path, _ in found]
    positions, shifts, widths = _tip_positions(points, subband, graph, [f[2] for f in found],
                                               dist_root, params)
    candidates: list[list[Candidate]] = [[] for _ in seeds]
    loop_sides: list[list[Candidate]] = [[] for _ in seeds]
    for (e, node, path, protrusion), side, extreme, position, shift, width, verdict, order in zip(
            found, sides or [False] * len(found), extremes, positions, shifts, widths, verdicts,
            orders):
        broad = _broad_corner(protrusion, width, params)
        if broad and params.candidate_floor <= 0 or side and (broad or not verdict):
            continue  # (over-generated far sides of loops are not kept for the tracks)
        root = points[seeds[e]]
        (loop_sides if side else candidates)[e].append(Candidate(
            position=position, node=node, geodesic=geodesic(graph, path),
            geodesic_approx=approximate_geodesic(position - shift, graph, path, root),
            path=graph.centroids[path], protrusion=protrusion, centre_shift=shift,
            extreme=None if extreme == node else extreme, width=float(width), order=order,
            thresholds=verdict and not broad, broad=broad))
    entities = [EntityEstimate(entity=e, root=points[seed], candidates=candidates[e],
                               graph=graph, point_index=np.flatnonzero(entity == e),
                               root_node=int(subband[seed]), loop_sides=loop_sides[e])
                for e, seed in enumerate(seeds)]
    timer.lap('extrema')
    unreachable = int(np.count_nonzero((entity >= 0) & (band == UNREACHED)))
    return FrameEstimate(points=points, band=band, subband=subband, entity=entity,
                         entities=entities, unreachable=unreachable, graph=graph,
                         stage_ms=timer.stages)


def _entities(points: npt.NDArray[np.float64], graph: Neighbours,
              dense: npt.NDArray[np.bool_], min_points: int,
              gap: float) -> npt.NDArray[np.intp]:
    """Entities: clusters of dense points, where clusters closer than ``gap`` are one entity
    (self-occlusion cuts a bending torso from its legs; such parts stay one entity). Entities
    with at least ``min_points`` points are labelled 0..E-1 by decreasing size, -1 elsewhere."""
    n = graph.n
    if n == 0:
        return np.zeros(0, dtype=np.intp)
    dense_i, dense_j = dense[graph.i], dense[graph.j]
    comp = graph.components(dense_i & dense_j)
    comp = _merge_close(points, comp, dense, gap)
    counts = np.bincount(comp[dense], minlength=int(comp.max()) + 1)
    big = np.flatnonzero(counts >= min_points)
    order = big[np.argsort(-counts[big], kind='stable')]
    remap = np.full(counts.size, -1, dtype=np.intp)
    remap[order] = np.arange(order.size)
    label = remap[comp]
    label[~dense] = -1
    # Sparse points (failing Eq. 3) next to an entity belong to it: they are never banded,
    # and so are counted as unreachable instead of vanishing from the report.
    for a, b, dense_a, dense_b in (((graph.i, graph.j, dense_i, dense_j),
                                    (graph.j, graph.i, dense_j, dense_i))
                                   if not dense.all() else ()):
        stray = ~dense_a & dense_b & (label[b] >= 0)
        label[a[stray]] = label[b[stray]]
    return label


#: :func:`_merge_close` compares two components' points pair by pair up to this many pairs
#: (cheaper than building a KD-tree of the larger one).
_MERGE_ALL_PAIRS = 20_000


def _merge_close(points: npt.NDArray[np.float64], comp: npt.NDArray[np.intp],
                 dense: npt.NDArray[np.bool_], gap: float) -> npt.NDArray[np.intp]:
    """Join components whose closest points are nearer than ``gap`` (union-find over the
    few components whose bounding boxes come that close; see ``close`` below)."""
    if gap <= 0:
        return comp
    # The dense points grouped by component (a stable sort keeps each group's order).
    idx = np.flatnonzero(dense)
    order = np.argsort(comp[idx], kind='stable')
    idx = idx[order]
    starts = np.flatnonzero(np.r_[True, np.diff(comp[idx]) != 0]) if idx.size else idx
    labels = comp[idx[starts]]
    if labels.size < 2:
        return comp
    members = np.split(idx, starts[1:])
    lo = np.minimum.reduceat(points[idx], starts, axis=0)
    hi = np.maximum.reduceat(points[idx], starts, axis=0)
    parent = np.arange(labels.size)

    def find(x: int) -> int:
        while parent[x] != x:
            x = parent[x]
        return x

    # Pairs whose bounding boxes come within the gap (row-major: a < b as a double loop).
    apart = ((lo[:, None, :] - hi[None, :, :] > gap).any(axis=2)
             | (lo[None, :, :] - hi[:, None, :] > gap).any(axis=2))
    trees: dict[int, cKDTree] = {}

    def close(small: int, large: int) -> bool:
        """A point of component ``small`` lies within the gap of one of ``large``: all
        distances when there are few (a stray point against the body: no tree to build),
        else the nearest one from a tree of ``large``."""
        near = points[members[small]]
        if len(near) * len(members[large]) <= _MERGE_ALL_PAIRS:
            diff = points[members[large]][None] - near[:, None]
            return bool((np.einsum('ijk,ijk->ij', diff, diff) < gap * gap).any())
        if large not in trees:  # (the nearest distance does not depend on the tree's shape)
            trees[large] = cKDTree(points[members[large]], balanced_tree=False,
                                   compact_nodes=False)
        d, _ = trees[large].query(near, distance_upper_bound=gap)
        return bool(np.isfinite(d).any())

    for a, b in zip(*np.nonzero(np.triu(~apart, k=1))):
        a, b = int(a), int(b)
        ra, rb = find(a), find(b)
        if ra == rb:
            continue
        if close(*((a, b) if len(members[a]) < len(members[b]) else (b, a))):
            parent[max(ra, rb)] = min(ra, rb)
    roots = np.array([find(x) for x in range(labels.size)])
    remap = np.zeros(int(comp.max()) + 1, dtype=np.intp)
    remap[labels] = labels[roots]
    return remap[comp]


def _roots(points: npt.NDArray[np.float64], graph: Neighbours,
           dense: npt.NDArray[np.bool_], entity: npt.NDArray[np.intp],
           params: EndeffParams) -> npt.NDArray[np.intp]:
    """Graph root per entity (Section 4.2): the point nearest the centroid starts a rough
    expansion; the centroid of its first N bands, snapped to the nearest point, is the root."""
    n_entities = int(entity.max()) + 1 if entity.size else 0
    if n_entities == 0:
        return np.zeros(0, dtype=np.intp)
    members = np.flatnonzero(entity >= 0)
    label = entity[members]
    cols = [np.ascontiguousarray(points[members, a]) for a in range(3)]
    rough = _nearest_to_centroids(cols, label, n_entities, np.ones(len(members), dtype=bool))
    bands = expand_bands(graph, dense, members[rough], params.band_delta,
                         max_bands=params.root_bands)
    massive = bands[members] != UNREACHED
    return members[_nearest_to_centroids(cols, label, n_entities, massive)]


def _nearest_to_centroids(cols: list[npt.NDArray[np.float64]], label: npt.NDArray[np.intp],
                          n: int, weight: npt.NDArray[np.bool_]) -> npt.NDArray[np.intp]:
    """Per label 0..n-1: index (into ``label``) of the point nearest the centroid of that
    label's points where ``weight``. ``cols`` are the x, y, z columns of the points; all
    labels at once (bincounts and one stable sort), not a pass per entity."""
    count = np.maximum(np.bincount(label[weight], minlength=n), 1)
    d2 = np.zeros(len(label))
    for c in cols:
        centre = np.bincount(label[weight], weights=c[weight], minlength=n) / count
        d2 += (c - centre[label]) ** 2
    if n == 1:
        return np.array([np.argmin(d2)], dtype=np.intp)
    order = np.lexsort((d2, label))  # by label, nearest first (ties: lowest index)
    first = np.r_[True, label[order][1:] != label[order][:-1]]
    return order[first]


def _group_quantile(values: npt.NDArray[np.float64], group: npt.NDArray[np.intp],
                    starts: npt.NDArray[np.intp], counts: npt.NDArray[np.intp],
                    q: float) -> npt.NDArray[np.float64]:
    """Lower-interpolated ``q`` quantile of ``values`` in each group (``group`` sorted, groups
    at ``starts`` with ``counts`` members, none empty): one sort for all groups."""
    order = np.lexsort((values, group))
    return values[order[starts + (q * (counts - 1)).astype(np.intp)]]


def _tip_positions(points: npt.NDArray[np.float64], subband: npt.NDArray[np.intp],
                   graph: TopologyGraph, paths: list[npt.NDArray[np.intp]],
                   dist_root: list[npt.NDArray[np.float64]],
                   params: EndeffParams) -> tuple[npt.NDArray[np.float64],
                                                  npt.NDArray[np.float64],
                                                  npt.NDArray[np.float64]]:
    """End-effector positions: the centre of each terminal part, not its outermost sliver.

    ``paths[m]`` runs from end-effector ``m``'s node to its root, ``dist_root[m]`` holds the
    geodesic distances of those nodes to the root. The terminal part is made of the path's
    sub-bands within ``tip_depth`` (geodesic) of the extreme node; its centroid lies on the
    *visible* surface. Limbs, hands, heads and most robot links are round, so the part's axis
    lies about one radius r behind that surface along the viewing ray; r is estimated from
    the visible width of the part across its axis (10th-90th percentile width / 1.6, exact
    for points uniform across a cylinder's silhouette) and capped at ``max_part_radius``.

    Along the part's axis (in the image plane) a rounded end's centre lies one radius inside
    the extreme, the 2 % quantile of the tip points along that axis: the centre of a head,
    wherever the tip region's centroid falls. A long part's centre lies deeper: a hand's is
    about half its length (9 cm) from the finger tips, more than its radius (3-4 cm). So the
    reported centre lies at the tip region's centroid along the axis, but between one radius
    (a round end) and one diameter (a part twice as long as wide: a hand, a shoe, a gripper)
    inside the extreme; the diameter bounds it where the tip region runs on into the next
    link or the radius is overestimated. Returns the centres (M, 3); for each, the shift
    along the axis from its rounded end's centre (M, 3), which the tracker follows: a
    stable point that does not move with the length of part that happens to be visible
    (docs/design.md: what the centre model buys); and the part's visible width across its
    axis (M,), uncapped (NaN where it has no axis), for :func:`_broad_corner`. Set
    ``max_part_radius`` to 0 to report the surface centroid. All end-effectors of the frame
    at once: per-point arrays labelled by end-effector, bincounts and one sort per quantile
    (one pass per end-effector cost ~0.2 ms each).
    """
    m = len(paths)
    no_shift = np.zeros((m, 3))
    no_width = np.full(m, np.nan)
    if m == 0:
        return no_shift, no_shift, no_width
    near = [path[d >= d[0] - params.tip_depth] for path, d in zip(paths, dist_root)]
    inner = np.array([path[min(len(path) - 1, len(n))] for path, n in zip(paths, near)])
    # Points of each terminal part, labelled by end-effector (parts may share nodes).
    tips = np.concatenate(near)
    by_node = np.argsort(subband, kind='stable')
    bounds = np.searchsorted(subband[by_node], np.arange(graph.n_nodes + 1))
    first, lengths = bounds[tips], bounds[tips + 1] - bounds[tips]
    point_idx = by_node[concat_ranges(first, lengths)]
    owner = np.repeat(np.repeat(np.arange(m), [len(n) for n in near]), lengths)
    tip = points[point_idx]
    counts = np.bincount(owner, minlength=m)
    starts = np.r_[0, np.cumsum(counts)[:-1]]
    centre = np.stack([np.bincount(owner, weights=tip[:, a], minlength=m) for a in range(3)],
                      axis=1) / np.maximum(counts, 1)[:, None]
    ray = centre / np.linalg.norm(centre, axis=1, keepdims=True)
    inward = graph.centroids[inner] - centre
    across = np.cross(inward, ray)
    norm = np.linalg.norm(across, axis=1)
    usable = (norm >= 1e-9) & (counts >= 3)
    if not usable.any():
        return centre, no_shift, no_width
    rel = tip - centre[owner]
    x = np.einsum('ij,ij->i', rel, across[owner] / np.maximum(norm, 1e-9)[owner, None])
    safe = np.maximum(counts, 1)
    p10 = _group_quantile(x, owner, starts, safe, 0.1)
    p90 = _group_quantile(x, owner, starts, safe, 0.9)
    width = np.where(usable, p90 - p10, np.nan)
    if params.max_part_radius <= 0:
        return centre, no_shift, width
    radius = np.minimum((p90 - p10) / 1.6, params.max_part_radius)
    # Along the axis, a rounded end's centre lies one radius inside its extreme: a head's
    # tip region is only its top cap, whose centroid sits above the head's centre; a long
    # tip region's centroid lies deeper inside than the end's centre.
    axis = inward - np.einsum('ij,ij->i', inward, ray)[:, None] * ray
    axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-9)
    extreme = _group_quantile(np.einsum('ij,ij->i', rel, axis[owner]), owner, starts, safe,
                              0.02)
    end = centre + (extreme + radius)[:, None] * axis + radius[:, None] * ray
    shift = (np.clip(-extreme, radius, 2.0 * radius) - radius)[:, None] * axis
    return (np.where(usable[:, None], end + shift, centre),
            np.where(usable[:, None], shift, 0.0), width)


def _broad_corner(protrusion: float, width: float, params: EndeffParams) -> bool:
    """Whether an extreme is the corner of a broad surface rather than the free end of a
    chain: it protrudes from the found paths less than ``min_end_aspect`` times the width of
    its terminal part (``tip_depth`` deep, across its axis).

    An end-effector ends a chain that is long for its width: a hand, a foot, a head, a chair's
    leg or a gripper protrudes several times its own width from the rest of the entity. The
    extremes that the iterated Dijkstra finds on a shoulder in a coat, a hip, the corner of a
    box or of a bulky body are short and as broad as the surface they bulge from. A ratio,
    not a width, so a near or a far, a small or a large entity is judged alike. The
    stubbiest true ends are heads between raised arms or beside a fist (about 0.24 m over
    0.15 m, 1.6); the choice of the ratio and its evidence are in docs/design.md. NaN widths
    (no axis) are kept.
    """
    return params.min_end_aspect > 0 and bool(protrusion < params.min_end_aspect * width)


class _StageTimer:
    """Wall-clock milliseconds per pipeline stage."""

    def __init__(self) -> None:
        self.stages: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.stages[name] = self.stages.get(name, 0.0) + (now - self._last) * 1e3
        self._last = now
