"""The single-frame estimator of Section 4 (the R-NBLS-style baseline): frame in, candidates out."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from .bands import UNREACHED, Neighbours, components, density_mask, expand_bands, split_subbands
from .cloud import FloorPlane, foreground_cloud
from .graph import (TopologyGraph, approximate_geodesic, build_graph, find_end_effectors,
                    geodesic)
from .params import EndeffParams
from .types import Candidate, RGBDFrame

if TYPE_CHECKING:
    import numpy.typing as npt


@dataclass(frozen=True)
class EntityEstimate:
    """One connected foreground cluster with its root, topology graph and candidates."""

    entity: int
    root: npt.NDArray[np.float64]
    candidates: list[Candidate]
    graph: TopologyGraph
    point_index: npt.NDArray[np.intp]
    root_node: int = 0
    rough_root: npt.NDArray[np.float64] | None = None


@dataclass(frozen=True)
class FrameEstimate:
    """Everything the Section 4 estimator found in one frame.

    ``points`` (N, 3) is the foreground after downsampling; ``band`` and ``subband`` label each
    point (-1 where the expansion never reached it), ``entity`` the cluster it belongs to (-1:
    too small). ``unreachable`` counts entity points that no band reached.
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

    def positions(self) -> npt.NDArray[np.float64]:
        """(M, 3) positions of all candidates of all entities."""
        rows = [c.position for e in self.entities for c in e.candidates]
        return np.array(rows, dtype=np.float64).reshape(-1, 3)


def estimate_frame(frame: RGBDFrame, params: EndeffParams | None = None, *,
                   floor: FloorPlane | None = None) -> FrameEstimate:
    """Run Sections 3-4 on one frame: foreground cloud, bands, graph, candidates.

    ``floor`` may give a known floor plane (the tracker passes the previous frame's).
    Raises :class:`~endeff_ros.core.errors.InputError` for unusable frames; an empty
    foreground is not an error (the estimate simply has no entities).
    """
    params = params or EndeffParams()
    timer = _StageTimer()
    points, floor = foreground_cloud(frame.depth, frame.intrinsics, params, floor=floor)
    timer.lap('cloud')
    estimate = estimate_points(points, params, timer=timer)
    return dataclasses.replace(estimate, floor=floor)


def estimate_points(points: npt.NDArray[np.float64], params: EndeffParams | None = None, *,
                    timer: _StageTimer | None = None) -> FrameEstimate:
    """Section 4 on a foreground cloud (N, 3), metres, optical frame."""
    params = params or EndeffParams()
    timer = timer or _StageTimer()
    neighbours = Neighbours.build(points, max(params.band_delta, params.attach_distance))
    within = (neighbours.within(params.band_delta)
              if params.attach_distance > params.band_delta else neighbours)
    dense = density_mask(within, params.band_eta)
    entity = _entities(within, dense, params.min_entity_points)
    timer.lap('neighbours')

    seeds, rough_roots = _roots(points, within, dense, entity, params)
    band = expand_bands(within, dense, seeds, params.band_delta)
    band[seeds] = 1  # L_0^0 joins the first band so the root node has the first band's size
    band[entity < 0] = UNREACHED
    timer.lap('bands')
    subband = split_subbands(points, neighbours, band, connect=params.band_delta,
                             max_points=params.subband_max_points,
                             min_points=params.subband_min_points)
    timer.lap('subbands')
    graph = build_graph(points, subband, band, neighbours,
                        attach_distance=params.attach_distance,
                        attach_points=params.attach_points)
    timer.lap('graph')

    entities = []
    for e, seed in enumerate(seeds):
        root_node = int(subband[seed])
        root = points[seed]
        candidates = []
        dist_root, _ = graph.shortest_paths([root_node])
        for node, path in find_end_effectors(graph, root_node,
                                             min_geodesic=params.min_geodesic,
                                             max_count=params.max_end_effectors):
            position = _tip_position(graph, path, dist_root, params.tip_depth)
            candidates.append(Candidate(
                position=position, node=node, geodesic=geodesic(graph, path),
                geodesic_approx=approximate_geodesic(position, graph, path, root),
                path=graph.centroids[path]))
        entities.append(EntityEstimate(entity=e, root=root, candidates=candidates,
                                       graph=graph, point_index=np.flatnonzero(entity == e),
                                       root_node=root_node, rough_root=rough_roots[e]))
    timer.lap('extrema')
    unreachable = int(np.count_nonzero((entity >= 0) & (band == UNREACHED)))
    return FrameEstimate(points=points, band=band, subband=subband, entity=entity,
                         entities=entities, unreachable=unreachable, graph=graph,
                         stage_ms=timer.stages)


def _entities(graph: Neighbours, dense: npt.NDArray[np.bool_],
              min_points: int) -> npt.NDArray[np.intp]:
    """Connected clusters of dense points with at least ``min_points`` points, labelled
    0..E-1 by decreasing size (-1 for everything else)."""
    n = graph.n
    if n == 0:
        return np.zeros(0, dtype=np.intp)
    both = dense[graph.i] & dense[graph.j]
    comp = components(n, graph.i[both], graph.j[both])
    counts = np.bincount(comp[dense], minlength=int(comp.max()) + 1)
    big = np.flatnonzero(counts >= min_points)
    order = big[np.argsort(-counts[big], kind='stable')]
    remap = np.full(counts.size, -1, dtype=np.intp)
    remap[order] = np.arange(order.size)
    label = remap[comp]
    label[~dense] = -1
    return label


def _roots(points: npt.NDArray[np.float64], graph: Neighbours,
           dense: npt.NDArray[np.bool_], entity: npt.NDArray[np.intp],
           params: EndeffParams) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.float64]]:
    """Graph root per entity (Section 4.2): the point nearest the centroid starts a rough
    expansion; the centroid of its first N bands, snapped to the nearest point, is the root."""
    n_entities = int(entity.max()) + 1 if entity.size else 0
    if n_entities == 0:
        return np.zeros(0, dtype=np.intp), np.zeros((0, 3))
    rough = np.array([_nearest(points, entity == e, _centroid(points, entity == e))
                      for e in range(n_entities)], dtype=np.intp)
    bands = expand_bands(graph, dense, rough, params.band_delta, max_bands=params.root_bands)
    massive = (bands != UNREACHED) & (entity >= 0)
    seeds = np.array([_nearest(points, entity == e,
                               _centroid(points, massive & (entity == e)))
                      for e in range(n_entities)], dtype=np.intp)
    return seeds, points[rough]


def _centroid(points: npt.NDArray[np.float64],
              mask: npt.NDArray[np.bool_]) -> npt.NDArray[np.float64]:
    return points[mask].mean(axis=0)


def _nearest(points: npt.NDArray[np.float64], mask: npt.NDArray[np.bool_],
             target: npt.NDArray[np.float64]) -> int:
    idx = np.flatnonzero(mask)
    return int(idx[np.argmin(np.einsum('ij,ij->i', points[idx] - target,
                                       points[idx] - target))])


def _tip_position(graph: TopologyGraph, path: npt.NDArray[np.intp],
                  dist_root: npt.NDArray[np.float64],
                  depth: float) -> npt.NDArray[np.float64]:
    """End-effector position: size-weighted centroid of the path's nodes within ``depth``
    (geodesic) of the extreme node, i.e. the centre of the terminal part rather than its
    outermost sliver."""
    d = dist_root[path]
    near = path[d >= d[0] - depth]
    w = graph.sizes[near].astype(np.float64)
    return (graph.centroids[near] * w[:, None]).sum(axis=0) / w.sum()


class _StageTimer:
    """Wall-clock milliseconds per pipeline stage."""

    def __init__(self) -> None:
        self.stages: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.stages[name] = self.stages.get(name, 0.0) + (now - self._last) * 1e3
        self._last = now
