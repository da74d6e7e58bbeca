"""The one typed parameter set of endeff_ros.

Every algorithm parameter lives in :class:`EndeffParams`, with the paper's symbol, unit, range
and meaning in its field metadata. The ROS node declares its parameters from this table, and
``config/endeff.yaml`` is generated from it (``endeff params --yaml``) and checked against it by
the tests, so the three never drift apart.

References
----------
Lin, Pardàs & Casas, *Time-consistent estimation of end-effectors from RGB-D data*, 2016.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from .errors import ParameterError


def _p(default: Any, doc: str, *, symbol: str = '', lo: float | None = None,
       hi: float | None = None, unit: str = '', runtime: bool = True) -> Any:
    """Declare a parameter field with its documentation and valid range."""
    return field(default=default, metadata={
        'doc': doc, 'symbol': symbol, 'lo': lo, 'hi': hi, 'unit': unit, 'runtime': runtime})


@dataclass(frozen=True)
class EndeffParams:
    """All tuning parameters; defaults suit a person 1-4 m from a Kinect/RealSense-class camera."""

    # --- Section 3: depth to foreground cloud -------------------------------------------------
    # x +-3.5 m: the sides do not cut people whom a wide-angle sensor (D435/D455, 87 degrees)
    # sees 2-3 m to the side. z to 5.25 m: people walking away from the camera stay in view
    # past 4 m, and the static background removes the room that comes in with them; deeper,
    # the false positives grew faster than the labels found (docs/design.md, "The box").
    box_min_x: float = _p(-3.5, 'Foreground box, minimum x (optical frame, right).', unit='m',
                          lo=-20.0, hi=20.0)
    box_max_x: float = _p(3.5, 'Foreground box, maximum x.', unit='m', lo=-20.0, hi=20.0)
    box_min_y: float = _p(-2.0, 'Foreground box, minimum y (optical frame, down).', unit='m',
                          lo=-20.0, hi=20.0)
    box_max_y: float = _p(2.0, 'Foreground box, maximum y.', unit='m', lo=-20.0, hi=20.0)
    box_min_z: float = _p(0.4, 'Foreground box, minimum z (depth).', unit='m', lo=0.0, hi=20.0)
    box_max_z: float = _p(5.25, 'Foreground box, maximum z (depth).', unit='m', lo=0.0, hi=20.0)
    pixel_stride: int = _p(2, 'Use every n-th pixel in u and v before back-projection.',
                           lo=1, hi=8)
    dropout_fill: bool = _p(True, 'A strided pixel without a reading takes the mean of the '
                            'readings in the 3 x 3 blocks of pixel_stride x pixel_stride pixels '
                            'around it, when at least two exist and they agree (one surface): '
                            'dark or distant parts that a ToF sensor reads in one pixel of ten '
                            'keep enough points for the density test (Eq. 3).')
    depth_median: bool = _p(False, '3x3 median filter on the depth image before back-projection '
                            '(removes flying pixels, thins noisy surfaces).')
    voxel_size: float = _p(0.03, 'Voxel grid cell for downsampling the foreground; 0 = off.',
                           unit='m', lo=0.0, hi=0.2)
    floor_removal: bool = _p(True, 'Fit the floor plane (RANSAC) and drop points on it.')
    floor_distance: float = _p(0.03, 'Points closer than this to the floor plane are floor.',
                               unit='m', lo=0.0, hi=0.5)
    floor_max_tilt_deg: float = _p(40.0, 'Floor normal must be within this angle of -y (up).',
                                   unit='deg', lo=0.0, hi=90.0)
    floor_min_fraction: float = _p(0.05, 'A floor must hold at least this fraction of points.',
                                   lo=0.0, hi=1.0)
    floor_iterations: int = _p(40, 'RANSAC hypotheses for the floor plane: as many planes '
                               'through random triples of points and as many local planes '
                               'around random points.', lo=1, hi=10000)
    wall_min_area: float = _p(1.0, 'Planes of any orientation that show at least this area '
                              'inside the box (walls, a wall behind a person) are not entities '
                              'and are dropped with the floor; 0 = off.', unit='m^2', lo=0.0,
                              hi=100.0)
    table_min_area: float = _p(0.3, 'Level surfaces above the floor (table tops, desks) whose '
                               'area less a 10 cm rim is at least this inside the box are not '
                               'entities and are dropped with the floor; 0 = off (needs '
                               'floor_removal).', unit='m^2', lo=0.0, hi=100.0)
    background: bool = _p(True, 'Static background: learn a per-pixel background depth while '
                          'running and drop the connected parts of the foreground that never '
                          'moved (furniture, walls); off for a camera that moves all the time '
                          'or people who never move.')
    background_keep_initial: bool = _p(True, 'Static background: what is in view while it '
                                       'learns (after the start or a reset) and holds an '
                                       'end-effector stays foreground for as long as it stays '
                                       'where it was, so a person who is already in view and '
                                       'keeps still is never hidden (false: the background drops '
                                       'it with what never moved, still people included).')
    background_keep_furniture: bool = _p(False, 'Static background: with '
                                         'background_keep_initial, also keep for good what is in '
                                         'view from the start and none of whose ends was ever '
                                         "taken for a person's (furniture). false: such an "
                                         'entity is learnt as background background_person_s '
                                         'after the learning.')
    background_person_s: float = _p(0.8, 'Static background: with background_keep_furniture '
                                    'false, the time after the learning within which an entity '
                                    "of the start must show ends taken for a person's (kind) "
                                    'to stay, and the window in which one that stayed is judged '
                                    'again for as long as it stays.', unit='s', lo=0.0,
                                    hi=3600.0)
    background_learn_s: float = _p(0.2, 'Static background: learning time after the start, a '
                                   'reset or a camera motion, during which nothing is removed.',
                                   unit='s', lo=0.0, hi=60.0)
    background_margin: float = _p(0.1, 'Static background: a pixel nearer than the background '
                                  'by more than this (plus 0.005 z^2 for depth noise) changed.',
                                  unit='m', lo=0.01, hi=2.0)
    background_absorb_s: float = _p(30.0, 'Static background: something nearer than the '
                                    'background and still for this long, holding no track, '
                                    'becomes background.', unit='s', lo=0.1, hi=86400.0)
    background_camera_motion_fraction: float = _p(0.08, 'Static background: when this fraction '
                                                  'of the pixels is nearer and another such '
                                                  'fraction farther, the camera moved and the '
                                                  'background is re-learnt.', lo=0.01, hi=1.0)

    # --- Section 4.1: narrow-band level-set expansion ------------------------------------------
    band_delta: float = _p(0.08, 'Proximity constraint: new band points lie within this '
                           'distance of the contour curve(t) (Eqs. 1-2).', symbol='δ_L',
                           unit='m', lo=0.005, hi=1.0)
    band_eta: int = _p(4, 'Density constraint: a point needs at least this many neighbours '
                       'within δ_L (Eq. 3).', symbol='η_L', lo=1, hi=1000)
    subband_max_points: int = _p(60, 'A sub-band (connected piece of a band) larger than this '
                                 'is split along its main axis.', lo=2, hi=100000)
    subband_min_points: int = _p(8, 'A sub-band smaller than this is merged into its '
                                 'best-connected neighbour (it could not be attached).',
                                 lo=1, hi=100000)
    root_bands: int = _p(6, 'Bands of the rough expansion whose points give the refined '
                         'centroid (size of the massive part, e.g. torso).', symbol='N',
                         lo=1, hi=1000)
    entity_gap: float = _p(0.25, 'Foreground clusters closer than this are one entity; the band '
                           'expansion bridges such occlusion gaps.', unit='m', lo=0.0, hi=2.0)
    steep_step_ratio: float = _p(4.0, 'Neighbours one behind the other: a pair of points is no '
                                 'neighbour when it is more than this many times farther apart '
                                 'along the viewing ray than across it, and farther than '
                                 'steep_step_min along it (a hand in front of the chest); '
                                 '4 keeps every surface seen within 76 degrees of head-on; '
                                 '0 = off.',
                                 lo=0.0, hi=100.0)
    steep_step_min: float = _p(0.04, 'Neighbours one behind the other: the least step along the '
                               'viewing ray that steep_step_ratio cuts.', unit='m', lo=0.0,
                               hi=1.0)
    color_edge_rgb: float = _p(0.0, 'Colour edges: a pair of neighbours whose mean colours (0-255 '
                               'RGB, Euclidean) differ by more than this and whose ranges '
                               'differ by more than color_edge_step is no neighbour (a hand '
                               'against the belly); needs the colour image; 0 = off.',
                               lo=0.0, hi=442.0)
    color_edge_step: float = _p(0.015, 'Colour edges: the least step along the viewing ray '
                                'that color_edge_rgb cuts.', unit='m', lo=0.0, hi=1.0)
    min_entity_points: int = _p(60, 'Connected foreground clusters smaller than this (after '
                                'downsampling) are ignored.', lo=1, hi=1000000)

    # --- Section 4.2: topology graph and extrema ------------------------------------------------
    attach_distance: float = _p(0.06, 'Attachment: points closer than this to the other '
                                'sub-band count towards attachment.', symbol='λ', unit='m',
                                lo=0.001, hi=1.0)
    attach_points: int = _p(2, 'Attachment: each sub-band needs at least this many points '
                            'within λ of the other.', symbol='P', lo=1, hi=10000)
    min_geodesic: float = _p(0.3, 'Iterated Dijkstra stops when the farthest node is closer '
                             'than this to the already found paths.', symbol='g', unit='m',
                             lo=0.0, hi=10.0)
    chain_geodesic: float = _p(0.2, 'Iterated Dijkstra also accepts an extreme closer than g '
                               'but not closer than this if it ends a chain: chain_subbands '
                               'sub-bands to the found paths, a local maximum of the geodesic '
                               'distance to the root, no sliver; >= g: g alone.',
                               unit='m', lo=0.0, hi=10.0)
    chain_subbands: int = _p(3, 'Sub-bands (edges) an extreme below g needs on its path to '
                             'the found paths (a chain, not one long edge of a broad surface).',
                             lo=1, hi=100)
    scale_length: float = _p(0.9, 'Relative thresholds: an entity whose first end-effector '
                             'lies closer than this to the root (a child, a small robot) has '
                             'g and chain_geodesic shrunk in the same proportion; 0 = off.',
                             unit='m', lo=0.0, hi=10.0)
    scale_min: float = _p(0.6, 'Relative thresholds: the least fraction of g and '
                          'chain_geodesic they shrink to (a body cut by the view, a small '
                          'piece of furniture).', lo=0.05, hi=1.0)
    max_end_effectors: int = _p(12, 'Upper bound on end-effectors per entity.', lo=1, hi=100)
    loop_far_sides: bool = _p(True, 'An extreme on the far side of a loop that a found path '
                              'runs through (the elbow of folded arms or clasped hands: its '
                              'two sides reach the found paths at points g or more apart) '
                              'is no end-effector: not reported, no new track starts on it, '
                              'a track already following it may keep it.')
    drop_cut_ends: bool = _p(True, 'Drop an end-effector whose sub-band reaches the image border '
                             '(within cut_margin_px), the foreground box (within one voxel) or '
                             'a dropped table top that hides the rest: it is where the view '
                             'cuts the body, not an end.')
    cut_margin_px: int = _p(3, 'How close (pixels) to the image border a sub-band counts as '
                            'cut by it.', unit='px', lo=0, hi=100)
    cut_dead_margins: bool = _p(True, 'Count the edge of the dead margins of registered depth '
                                '(bands or corners along the border where the sensor never '
                                'reads, learnt from the stream) as the image border for cut '
                                'ends where they are at least 5 % of the image deep; an edge '
                                "that is no straight line along a side is the scene's, not a "
                                'margin.')
    tip_depth: float = _p(0.14, 'Geodesic depth of the terminal part behind its extreme: '
                          'its points give the part radius, axis and centre.', unit='m',
                          lo=0.0, hi=1.0)
    min_tip_points: int = _p(4, 'An extreme whose terminal part (tip_depth deep) holds fewer '
                             'points is a sliver (a surface seen edge-on that the path ran '
                             'on through): the end-effector is the first sub-band back along '
                             'its path whose terminal part holds this many; 0 = off.',
                             lo=0, hi=1000)

    max_part_radius: float = _p(0.1, 'Cap on the terminal-part radius used to move the '
                                'end-effector from the visible surface to the part centre; '
                                '0 reports the surface.', unit='m', lo=0.0, hi=0.5)
    min_end_aspect: float = _p(1.5, 'An end protrudes from the found paths at least this '
                               'many times the width of its terminal part (tip_depth deep, '
                               'across its axis); a shorter, broader extreme is the corner of '
                               'a broad surface (a shoulder in a coat, a hip, a box) and is '
                               'dropped; 0 = off.', lo=0.0, hi=20.0)
    candidate_floor: float = _p(0.12, 'Over-generate: the iterated Dijkstra goes on past g and '
                                'the chain rule down to extremes that protrude this much, and '
                                'broad corners and cut ends are kept, each marked with the '
                                "thresholds' verdict, for the candidate scorer "
                                '(core/candidates.py); 0 = off: the thresholds decide alone.',
                                unit='m', lo=0.0, hi=10.0)
    candidate_scorer: bool = _p(True, 'With candidate_floor > 0: keep the candidates that the '
                                "committed model (core/candidate_model.json) gives at least "
                                "min_candidate_score; off: the thresholds' verdicts.")
    min_candidate_score: float = _p(0.4, 'Candidate scorer: the least chance of being an '
                                    'end-effector a candidate that the thresholds pass over '
                                    'needs to be kept.', lo=0.0, hi=1.0)
    drop_candidate_score: float = _p(0.15, 'Candidate scorer: a candidate that the thresholds '
                                     'keep is dropped only when its chance of being an '
                                     'end-effector is below this.', lo=0.0, hi=1.0)

    # --- Section 5: predict-update tracking ------------------------------------------------------
    flow_method: str = _p('dis', "Dense optical flow for the predict phase: 'dis' or "
                          "'farneback' (LDOF is not in OpenCV).", runtime=False)
    related_similarity: float = _p(0.5, 'Case A: matched candidates with similarity above '
                                   'this are the same end-effector.', symbol='ε_a',
                                   lo=0.0, hi=1.0)
    unrelated_ratio: float = _p(1.0, 'Case B lower bound: ε_b is this factor over '
                                '(1 + max(dist_G(e1), dist_G(e2))) as a similarity.',
                                symbol='ε_b', lo=0.0, hi=10.0)
    # A candidate off the track's limb is another end-effector, not this one replaced by a
    # part of its limb (docs/design.md, "Case B stays on the limb").
    case_b_path_distance: float = _p(0.2, 'Case B only for a candidate within this distance '
                                     'of the path the track reached the root by when last '
                                     'detected (its own limb: the elbow of a hand on the '
                                     'chest); farther, the track goes on in case C and the '
                                     'candidate starts its own track; 0 = off.', unit='m',
                                     lo=0.0, hi=10.0)
    similarity_scale: float = _p(0.15, 'Similarity = 1 / (1 + geodesic / scale) between two '
                                 'candidates in the current graph.', unit='m', lo=0.001,
                                 hi=10.0)
    keep_frames: int = _p(8, 'Case C: an unmatched predicted end-effector is kept at most '
                          'this many frames, and no more frames than it was detected in.',
                          symbol='T', lo=0, hi=1000)
    confirm_hits: int = _p(4, 'Case C keeps only tracks that current candidates supported in '
                           'at least this many frames (1: every track).', lo=1, hi=1000)
    memory_sigma: float = _p(0.99, 'Geodesic memory penalty, α = σ^k (Eqs. 8-9).', symbol='σ',
                             lo=0.0, hi=1.0)
    duplicate_distance: float = _p(0.03, 'A predicted end-effector closer than this to a '
                                   'detected (or longer-memory) one is dropped as a duplicate '
                                   '(less than the ~8 cm between touching hands).',
                                   unit='m', lo=0.0, hi=1.0)
    max_rectify_distance: float = _p(0.15, 'A prediction farther than this from every '
                                     'current point is dropped.', unit='m', lo=0.0, hi=5.0)
    revive_distance: float = _p(0.3, 'A new end-effector this close to where a track was '
                                'lost within the last T frames takes its id back, and one '
                                'on the limb of a track that has just gone on its '
                                'prediction continues that track (0: never).', unit='m',
                                lo=0.0, hi=5.0)
    revive_frames: int = _p(30, 'A track dropped at most this many frames ago gives its id back '
                            '(revive_distance).', lo=0, hi=10000)
    # A fast end (a foot in a cartwheel, a kick) is often found again farther than
    # revive_distance from where it was lost; its geodesic distance to the root, its kind and
    # its direction from the root tell its limb (the measurements: Tracker._revived_ids;
    # docs/design.md, "An id comes back").
    revive_far_distance: float = _p(0.8, 'A new end-effector farther than revive_distance but '
                                    'within this distance of where a track was lost takes its '
                                    'id back only if its geodesic distance to the root (Eq. 7) '
                                    'is within revive_geodesic_tolerance of the one the track '
                                    'memorised (Eq. 8), it leaves the root the same way and '
                                    'neither is a head: the same limb found again after a fast '
                                    'move (0: off).', unit='m', lo=0.0, hi=5.0)
    revive_geodesic_tolerance: float = _p(0.3, 'Largest difference between the geodesic '
                                          'distance to the root of a new end-effector and of '
                                          'a lost track for the id to come back from beyond '
                                          'revive_distance (revive_far_distance).', unit='m',
                                          lo=0.0, hi=5.0)
    # Published positions: One Euro filter along each track (Casiez et al. 2012; names as
    # the paper's), the velocity from it (core/smoothing.py).
    smoothing: bool = _p(True, 'Publish the position of each track filtered along it (One '
                         'Euro filter); off: the raw detection or prediction (the velocity '
                         'is filtered either way).')
    smoothing_min_cutoff: float = _p(0.3, 'One Euro filter: cutoff frequency of a still '
                                     'end-effector (lower: smoother when still, more lag '
                                     'when slow).', symbol='min_cutoff', unit='Hz', lo=0.01,
                                     hi=100.0)
    smoothing_beta: float = _p(10.0, 'One Euro filter: cutoff increase per m/s of speed; the '
                               'lag of a fast end-effector approaches 1 / (2π beta).',
                               symbol='beta', unit='s/m', lo=0.0, hi=1000.0)
    smoothing_d_cutoff: float = _p(0.5, 'One Euro filter: cutoff frequency of the velocity '
                                   'estimate (the published velocity and the speed that '
                                   'raises the cutoff).', symbol='d_cutoff', unit='Hz',
                                   lo=0.01, hi=100.0)
    smoothing_max_lag: float = _p(0.05, 'A filtered position is never farther than this from '
                                  'the raw one (0: unbounded).', unit='m', lo=0.0, hi=1.0)
    smoothing_reset_distance: float = _p(0.2, 'A raw step longer than this between frames is '
                                         'the track moving to another point, not motion: its '
                                         'filter starts again there, velocity zero (0: '
                                         'never).', unit='m', lo=0.0, hi=10.0)
    # Confidence: the chance an end is right, scored from its evidence (core/confidence.py).
    scored_confidence: bool = _p(True, "Publish as confidence the committed model's chance "
                                 'that the end is right (core/confidence_model.json); off: '
                                 "the paper's memory weight σ^k (T + 1 - m) / (T + 1).")
    scored_kinds: bool = _p(True, "Decide which ends are people's and which is the head with "
                            'the committed person and head models (core/kind_model.json); '
                            'off: the geometric rules of core/kinds.py alone.')
    min_confidence: float = _p(0.0, 'Publish only end-effectors whose confidence is at least '
                               'this (the operating point between recall and false ends); '
                               'the others are still tracked.', lo=0.0, hi=1.0)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            want = type(f.default)
            ok = (isinstance(value, (int, float)) and not isinstance(value, bool)
                  if want is float else type(value) is want)
            if not ok:
                msg = f'parameter {f.name} must be {want.__name__}, got {value!r}'
                raise ParameterError(msg)
            lo, hi = f.metadata['lo'], f.metadata['hi']
            if isinstance(value, bool) or isinstance(value, str):
                continue
            if lo is not None and value < lo or hi is not None and value > hi:
                msg = f'parameter {f.name}={value!r} is outside [{lo}, {hi}]'
                raise ParameterError(msg)
        for axis in 'xyz':
            if getattr(self, f'box_min_{axis}') >= getattr(self, f'box_max_{axis}'):
                msg = f'foreground box: box_min_{axis} must be smaller than box_max_{axis}'
                raise ParameterError(msg)
        if self.flow_method not in ('dis', 'farneback'):
            msg = f"flow_method must be 'dis' or 'farneback', not {self.flow_method!r}"
            raise ParameterError(msg)

    def replace(self, **changes: Any) -> EndeffParams:
        """Return a copy with ``changes`` applied (validated)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> EndeffParams:
        """Build from a flat mapping; unknown keys and wrong types are errors."""
        known = {f.name: f for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - set(known))
        if unknown:
            msg = f'unknown parameter(s): {", ".join(unknown)}'
            raise ParameterError(msg)
        typed = {}
        for name, value in values.items():
            want = type(known[name].default)
            if want is float and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            if type(value) is not want:
                msg = f'parameter {name} must be {want.__name__}, got {value!r}'
                raise ParameterError(msg)
            typed[name] = value
        return cls(**typed)

    def to_dict(self) -> dict[str, Any]:
        """Flat mapping of every parameter."""
        return dataclasses.asdict(self)


def describe() -> list[dict[str, Any]]:
    """One row per parameter: name, type, default, doc, symbol, unit, lo, hi, runtime."""
    rows = []
    for f in dataclasses.fields(EndeffParams):
        rows.append({'name': f.name, 'type': type(f.default).__name__, 'default': f.default,
                     **f.metadata})
    return rows


NODE_NAME = 'endeff_node'

#: Named parameter sets shipped as ``config/endeff_<name>.yaml`` (besides ``config/endeff.yaml``,
#: the defaults). ``fast``: 4 cm voxels (932 instead of 1394 points on the benchmark frame),
#: the sub-band sizes and the sliver threshold scaled with the voxel area; δ_L and λ
#: unchanged. It trades some accuracy for about 0.7x the time per frame (docs/results.md),
#: and its 4 cm cells are too coarse for the 5 cm tip tests on the unit-test shapes, so it is
#: not the default. Its smaller sub-bands cut a limb into more pieces, so a chain below g
#: needs 4 sub-bands (docs/design.md).
PRESETS: dict[str, dict[str, Any]] = {
    'fast': {'voxel_size': 0.04, 'subband_max_points': 34, 'subband_min_points': 4,
             'min_tip_points': 2, 'chain_subbands': 4},
}


def to_ros_yaml(params: EndeffParams | None = None, node_name: str = '/**') -> str:
    """Render the parameter set as a ROS 2 parameter file (``config/endeff.yaml``).

    The default key ``/**`` matches the node in any namespace (``endeff_node:`` would only
    match a node in the root namespace, not ``/camera/endeff_node``).
    """
    params = params or EndeffParams()
    lines = ['# Generated from endeff_ros.core.params.EndeffParams by `endeff params --yaml`.',
             '# Do not edit by hand: a test checks this file against the dataclass.',
             f"'{node_name}':" if node_name.startswith('/') else f'{node_name}:',
             '  ros__parameters:']
    for row in describe():
        symbol = f' [{row["symbol"]}]' if row['symbol'] else ''
        unit = f' ({row["unit"]})' if row['unit'] else ''
        lines.append(f'    # {row["doc"]}{symbol}{unit}')
        value = getattr(params, row['name'])
        if isinstance(value, bool):
            text = 'true' if value else 'false'
        elif isinstance(value, str):
            text = f"'{value}'"
        else:
            text = repr(value)
        lines.append(f'    {row["name"]}: {text}')
    return '\n'.join(lines) + '\n'


def load_yaml(path: str, node_name: str = NODE_NAME) -> EndeffParams:
    """Read a ROS 2 parameter file (or a flat YAML mapping) into :class:`EndeffParams`."""
    import yaml

    with open(path, encoding='utf-8') as fh:
        data = yaml.safe_load(fh) or {}
    if not isinstance(data, dict):
        msg = f'{path}: expected a mapping of parameters'
        raise ParameterError(msg)
    for key in (node_name, '/**'):
        if key in data and isinstance(data[key], dict):
            data = data[key].get('ros__parameters', data[key])
            break
    return EndeffParams.from_dict(data)
