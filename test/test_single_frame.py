"""Section 4 of the core: bands (Eqs. 1-4), topology graph (Eqs. 5-7) and the single-frame
estimator on synthetic depth frames with known end-effectors.

Scenes come from :mod:`endeff_ros.synth.scenes`: the benchmark suites' own bodies ray-cast
into an ideal 640x480 depth image (the same renderer as the bags), with the suites' ground
truth, the CENTRE of each terminal part (head, palm, shoe, a star limb's end cap, a chair leg's
foot, the gripper; see docs/benchmark-bags.md). Ground truth is matched to candidates one to
one (Hungarian matching on the Euclidean distance).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
import pytest
import scenarios as sc
from scipy import sparse
from scipy.sparse import csgraph
from scipy.spatial.transform import Rotation

from endeff_ros.core import bands
from endeff_ros.core.assignment import min_cost_assignment
from endeff_ros.core.bands import (
    UNREACHED,
    Neighbours,
    density_mask,
    expand_bands,
    split_subbands,
)
from endeff_ros.core.cloud import foreground_cloud
from endeff_ros.core.graph import (
    TopologyGraph,
    approximate_geodesic,
    build_graph,
    distance_to_path,
    find_end_effectors,
    geodesic,
)
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.single_frame import estimate_frame, estimate_points
from endeff_ros.core.types import KINECT_640, RGBDFrame
from endeff_ros.synth import scenes
from endeff_ros.synth.body import (
    HEAD,
    LEFT_FOOT,
    LEFT_HAND,
    RIGHT_FOOT,
    RIGHT_HAND,
    PersonModel,
    PersonStyle,
)
from endeff_ros.synth.proc_clips import walk_clip
from endeff_ros.synth.render import Camera
from endeff_ros.synth.skeleton_body import BodyStyle, build_body
from endeff_ros.synth.views import View, aim_camera, place

#: m, ground truth to its matched candidate. The terminal parts of the person, the star and
#: the chair legs reach at most 0.12 m (a shoe's half length) from their centre, and the found
#: end lies on the part, pushed behind its visible surface by the part radius (Section 4): the
#: measured errors are 0.7-4.1 cm.
TIP_TOLERANCE = 0.05
#: m, the chair's legs: their ground truth is the leg's foot (3 cm up), but a leg is a long
#: part, whose centre the estimator reports deeper than its rounded end (the rule that puts a
#: hand's centre inside the palm, ``_tip_positions``): the measured errors are 4.3-7.5 cm.
CHAIR_TOLERANCE = 0.08
#: m, the robot arm's ground truth: its terminal parts end far from their centres (the fingers
#: reach 0.12 m beyond the gripper's centre, the pedestal's bottom corners 0.17 m from its
#: bottom centre), so the found ends lie 8.5-14.4 cm from the ground truth (the suite's
#: robot_arm error is 8.5 cm, docs/results.md). This is the benchmark's true-positive
#: threshold (docs/benchmark-bags.md); that the end lies ON the part is checked separately.
ARM_TOLERANCE = 0.15
#: m, the pedestal's end: its square base has two bottom corners, 0.08-0.21 m from the bottom
#: centre that labels it (the floor hides the rest). In the first arm scene the corner found
#: second protrudes 0.27 m for a tip 0.22 m wide, no end by ``min_end_aspect`` (a broad
#: corner), so the one reported is the corner found first, 0.21 m away; that it lies on
#: the pedestal is checked separately (ON_GRIPPER).
PEDESTAL_TOLERANCE = 0.22
#: m, a found end to the solid of its ground truth's terminal part (0 inside): the part-radius
#: step puts it inside; 2 cm allows for the sub-band centroid on a thin part's surface.
ON_PART = 0.02
#: m, the same for the robot arm's gripper: its fingers are separate parts reaching 0.12 m
#: beyond the gripper box's centre, and the end found at their tips lies 2.4-3.7 cm outside
#: the box.
ON_GRIPPER = 0.04


def match(tips, candidates):
    """Hungarian matching: (tip index, candidate index, distance) arrays."""
    tips, candidates = np.asarray(tips).reshape(-1, 3), np.asarray(candidates).reshape(-1, 3)
    if len(tips) == 0 or len(candidates) == 0:
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0)
    d = np.linalg.norm(tips[:, None] - candidates[None], axis=2)
    rows, cols = min_cost_assignment(d)
    return rows, cols, d[rows, cols]


def tip_errors(tips, candidates):
    """Per-tip distance to its matched candidate (inf for tips left without one)."""
    rows, _, dist = match(tips, candidates)
    errors = np.full(len(tips), np.inf)
    errors[rows] = dist
    return errors


def set_distance(a, b):
    """Largest matched distance between two point sets of the same size (inf otherwise)."""
    a, b = np.asarray(a).reshape(-1, 3), np.asarray(b).reshape(-1, 3)
    if len(a) != len(b):
        return math.inf
    return float(match(a, b)[2].max()) if len(a) else 0.0


def frame(depth):
    return RGBDFrame(stamp_ns=0, frame_id='camera', depth=depth, intrinsics=KINECT_640)


# ---------------------------------------------------------------------------------------------
# Synthetic scenes with known end-effectors
# ---------------------------------------------------------------------------------------------

#: The thresholds of Section 4 alone, no candidate scorer: the tests of a threshold's own
#: verdict (the chain rule, relative thresholds, cut ends), which the scorer weighs as evidence.
RULES = {'candidate_floor': 0.0}
#: The chair is seen from 0.4 m up, below its seat (0.46 m), so the seat hides no leg.
LOW = Camera(KINECT_640, height=0.4, pitch=0.0, frame_id='camera')
#: Robot arm joint angles (base yaw, shoulder, elbow, wrist; rad) of the two arm scenes.
ARM_Q = {0: (0.6, 0.7, 1.2, 0.3), 1: (-0.5, 0.3, 0.8, -0.3)}
#: The parts a root may lie in: the entity's massive part (the star's hub, the person's trunk,
#: the chair's seat, the arm's pedestal and links but not its gripper).
MASSIVE = {'star': {'hub'}, 'person': {'pelvis', 'abdomen', 'chest'}, 'chair': {'seat'},
           'arm': {'pedestal', 'turret', 'link1', 'link2'}}
#: The chair's backrest corners (ground-truth ids 4, 5): see test_chair_backrest_corners.
CHAIR_LEGS = [0, 1, 2, 3]


def _entity(kind, arg, variant):
    if kind == 'star':  # variant: the first limb's angle (rad)
        return scenes.star(arg, spin=variant)
    if kind == 'person':  # variant: yaw (rad)
        return scenes.person(arg, yaw=variant)
    if kind == 'chair':  # arg: yaw, variant: x (m)
        return scenes.placed_chair(arg, x=variant)
    return scenes.placed_robot_arm(ARM_Q[variant])


def _shoot(kind, entity, camera=None):
    camera = camera or (LOW if kind == 'chair' else scenes.LEVEL)
    return scenes.shoot(entity, camera, floor=kind != 'star')  # the star floats in the air


@functools.cache
def rendered(kind, arg, variant):
    """The scene's ``scenes.Shot``, rendered once per test session."""
    return _shoot(kind, _entity(kind, arg, variant))


@functools.cache
def estimated(kind, arg, variant):
    shot = rendered(kind, arg, variant)
    return estimate_frame(shot.frame, EndeffParams()), shot


def scored(kind):
    """The ground-truth ids a scene test scores (the chair's backrest corners are no ends:
    test_chair_backrest_corners) and their tolerance."""
    return (CHAIR_LEGS if kind == 'chair' else slice(None),
            {'arm': np.array([PEDESTAL_TOLERANCE, ARM_TOLERANCE]),
             'chair': CHAIR_TOLERANCE}.get(kind, TIP_TOLERANCE))


CASES = [
    *(pytest.param('star', n, spin, id=f'star{n}-spin{spin}') for n in (3, 4, 5, 6)
      for spin in (0.3, 1.0)),
    *(pytest.param('person', pose, yaw, id=f'{pose}-yaw{yaw}')
      for pose in ('t_pose', 'arms_down') for yaw in (0.0, 0.35)),
    *(pytest.param('chair', yaw, x, id=f'chair-yaw{yaw}-x{x}') for yaw in (0.5, -0.5)
      for x in (0.0, 0.2)),
    *(pytest.param('arm', None, q, id=f'robot_arm-q{q}') for q in ARM_Q),
]


def test_scenes_are_visible():
    """Premise of the scene tests: every end-effector projects inside the image, in front of
    the camera, and its own part is what the camera sees there (the chair's back legs too:
    the low camera looks under the seat)."""
    for case in CASES:
        shot = rendered(*case.values)
        uv = KINECT_640.project(shot.gt)
        assert np.all(shot.gt[:, 2] > 0.5), case.id
        assert np.all((uv >= 5) & (uv < [KINECT_640.width - 5, KINECT_640.height - 5])), case.id
        assert shot.gt_visible.all(), case.id


def _ends_on_their_parts(shot, positions, ids):
    """(errors, distances to the terminal part) of ground truth ``ids`` and their matched
    candidates; inf where a ground truth has no candidate."""
    gt = shot.gt[ids]
    errors = tip_errors(gt, positions)
    rows, cols, _ = match(gt, positions)
    on_part = np.full(len(gt), np.inf)
    index = np.arange(len(shot.gt))[ids]
    for r, c in zip(rows, cols):
        on_part[r] = scenes.distance_to_part(shot.part(index[r]), positions[c][None])[0]
    return errors, on_part


_LEGS_DROPPED = pytest.mark.xfail(strict=True, reason=(
    'the candidate scorer drops two legs of the chair seen from 0.4 m up that the thresholds '
    'keep (scored below drop_candidate_score); thresholds alone find all four'))


@pytest.mark.parametrize('kind, arg, variant', [
    pytest.param(*c.values, id=c.id, marks=[_LEGS_DROPPED] if c.id in (
        'chair-yaw0.5-x0.0', 'chair-yaw-0.5-x0.2') else []) for c in CASES])
def test_every_end_effector_found_on_its_part(kind, arg, variant):
    """Each end-effector has a candidate within the tolerance of its ground truth, and that
    candidate lies on the end-effector's own terminal part (not on the limb before it)."""
    est, shot = estimated(kind, arg, variant)
    ids, tolerance = scored(kind)
    errors, on_part = _ends_on_their_parts(shot, est.positions(), ids)
    assert np.all(errors < tolerance), f'errors {np.round(errors, 3)}'
    limit = ON_GRIPPER if kind == 'arm' else ON_PART
    assert np.all(on_part <= limit), f'distance to the part {np.round(on_part, 3)}'


@functools.cache
def coat_walker(index):
    """Frame ``index`` of the procedural walk, worn by a person in a coat (the mocap suite's
    body), seen from the front at 3 m."""
    view = View('front', 3.0, 1.3)
    joints, _ = place(walk_clip(60).positions[index:index + 1], view)
    return scenes.shoot(build_body(joints[0], BodyStyle(clothing='coat')),
                        aim_camera(joints, view, KINECT_640))


@pytest.mark.parametrize('index', [5, 25, 45])
def test_a_bulge_of_a_coat_is_no_end(index):
    """The coat's front at chest height, nearer the camera than the rest of the body, is an
    extreme of the graph 0.45 m from every end-effector, but it protrudes less than 1.5 times
    its own width (``min_end_aspect``): no end. The true ends found without the rule are all
    still found with it."""
    shot = coat_walker(index)

    def far_from_labels(positions):
        return np.array([np.linalg.norm(shot.gt - p, axis=1).min() > 0.25 for p in positions],
                        dtype=bool).reshape(-1)

    without = estimate_frame(shot.frame, EndeffParams(min_end_aspect=0.0,
                                                      loop_far_sides=False)).positions()
    assert far_from_labels(without).any()  # the premise: the bulge is there
    found = estimate_frame(shot.frame, EndeffParams()).positions()
    assert not far_from_labels(found).any(), np.round(found, 3)
    true = without[~far_from_labels(without)]
    assert set_distance(found, true) < 1e-9


@pytest.mark.parametrize('yaw', [0.0, 0.35])
def test_a_hand_is_reported_at_its_centre_and_a_head_at_its_rounded_end(yaw):
    """A hand is a long part: its centre (the ground truth, inside the palm) lies deeper
    than its rounded end, and the candidate is shifted there along the part's axis, by at
    most the part radius. A head is a round end: little or no shift. The tracker follows the
    rounded end (``end_centre``)."""
    est, shot = estimated('person', 't_pose', yaw)
    cands = [c for e in est.entities for c in e.candidates]
    positions = np.array([c.position for c in cands])
    nearest = {k: cands[int(np.argmin(np.linalg.norm(positions - shot.gt[k], axis=1)))]
               for k in (HEAD, LEFT_HAND, RIGHT_HAND)}
    for k, c in nearest.items():
        shift = np.linalg.norm(c.centre_shift)
        assert shift <= EndeffParams().max_part_radius + 1e-9
        np.testing.assert_allclose(c.end_centre + c.centre_shift, c.position)
        # The shift never takes an end away from its part's centre; a head moves little.
        assert (np.linalg.norm(c.position - shot.gt[k])
                <= np.linalg.norm(c.end_centre - shot.gt[k]) + 1e-3)
        if k == HEAD:
            assert shift < 0.015, shift
    hands = [nearest[LEFT_HAND], nearest[RIGHT_HAND]]
    assert max(np.linalg.norm(c.centre_shift) for c in hands) > 0.02  # a hand is shifted
    if yaw == 0.0:  # both hands seen along their length: within 2 cm of their centres
        errors = tip_errors(shot.gt[[LEFT_HAND, RIGHT_HAND]],
                            np.array([c.position for c in hands]))
        assert errors.max() < 0.02, errors


@pytest.mark.parametrize('kind, arg, variant', [
    pytest.param('star', 5, 0.3, id='star'), pytest.param('person', 't_pose', 0.0, id='person'),
    pytest.param('chair', 0.5, 0.0, id='chair')])
def test_end_effector_check_fails_on_a_wrong_scene(kind, arg, variant):
    """The check above can fail: a limb missing from the rendered scene (its end-effector has
    no candidate), or the scene moved 0.1 m sideways from its ground truth."""
    est, shot = estimated(kind, arg, variant)
    ids, tolerance = scored(kind)
    entity = _entity(kind, arg, variant)
    limb = {'star': ('limb0_a', 'limb0_b', 'limb0_cap'), 'person': ('head', 'neck'),
            'chair': ('leg0',)}[kind]  # the parts of ground truth 0 and those holding it
    entity.prims = [p for p in entity.prims if p.part not in limb]
    missing = estimate_frame(_shoot(kind, entity).frame, EndeffParams()).positions()
    errors, _ = _ends_on_their_parts(shot, missing, ids)
    assert errors[0] > tolerance, np.round(errors, 3)
    moved = est.positions() + [0.1, 0.0, 0.0]
    errors, on_part = _ends_on_their_parts(shot, moved, ids)
    assert np.any(errors > tolerance) and np.any(on_part > ON_PART)


@pytest.mark.parametrize('kind, arg, variant', [
    *CASES])
def test_nothing_else_is_reported(kind, arg, variant):
    """One entity and no extra candidate: at most one per end-effector (a missed one is the
    business of test_every_end_effector_found_on_its_part; the chair's backrest gives at
    most one end for its two corners)."""
    est, shot = estimated(kind, arg, variant)
    assert len(est.entities) == 1
    assert len(est.positions()) <= len(shot.gt), np.round(est.positions(), 3)


@pytest.mark.xfail(strict=True, reason=(
    'the backrest is a solid panel: its two top corners are no separate ends (no end at all '
    "from this 0.4 m camera; from the suite's camera one at its top centre, 23 cm from each "
    'corner: docs/results.md)'))
@pytest.mark.parametrize('yaw', [0.5, -0.5])
def test_chair_backrest_corners(yaw):
    est, shot = estimated('chair', yaw, 0.0)
    errors = tip_errors(shot.gt[4:], est.positions())
    assert np.all(errors < TIP_TOLERANCE), np.round(errors, 3)


@pytest.mark.parametrize('kind, arg, variant', CASES)
def test_root_lies_in_the_massive_part(kind, arg, variant):
    """The root (the foreground point nearest the entity's centre, Section 4) is on the
    entity's massive part: within ON_PART of one of its solids."""
    est, shot = estimated(kind, arg, variant)
    assert len(est.entities) >= 1
    root = est.entities[0].root
    distance = min(scenes.distance_to_part(p, root[None])[0] for p in shot.prims
                   if p.part in MASSIVE[kind])
    assert distance <= ON_PART, f'root {np.round(root, 3)}: {distance:.3f} m off'
    # The root is a foreground point of its entity.
    assert np.min(np.linalg.norm(est.points - root, axis=1)) < 1e-9


@pytest.mark.parametrize('pose', ['t_pose', 'arms_down'])
@pytest.mark.parametrize('yaw', [0.0, 0.35])
def test_person_hands_and_feet(pose, yaw):
    """Hands and both feet within 5 cm; the feet, standing on the floor, stay two separate
    ends after floor removal (one candidate each)."""
    est, shot = estimated('person', pose, yaw)
    assert est.floor is not None
    assert est.floor.normal @ [0.0, -1.0, 0.0] > math.cos(math.radians(1.0))
    assert est.floor.offset == pytest.approx(scenes.LEVEL.height, abs=0.01)
    rows, cols, dist = match(shot.gt, est.positions())
    by_tip = dict(zip(rows.tolist(), zip(cols.tolist(), dist.tolist())))
    for t in (LEFT_HAND, RIGHT_HAND, LEFT_FOOT, RIGHT_FOOT):
        assert t in by_tip and by_tip[t][1] < TIP_TOLERANCE, (t, by_tip.get(t))
    left_foot, right_foot = by_tip[LEFT_FOOT][0], by_tip[RIGHT_FOOT][0]
    assert left_foot != right_foot
    # The ankles are 0.24 m apart; each candidate is on its own side (the person's left is
    # the camera's right).
    positions = est.positions()
    assert positions[left_foot][0] > 0.06 and positions[right_foot][0] < -0.06


# ---------------------------------------------------------------------------------------------
# Camera motion on the depth path (approximate: pixels and voxels do not move with the scene)
# ---------------------------------------------------------------------------------------------

#: (pitch down, yaw to the left, roll clockwise) of the turned camera, rad.
TURNS = {'pitch-down': (math.radians(10), 0.0, 0.0), 'pitch-up': (math.radians(-10), 0.0, 0.0),
         'yaw': (0.0, math.radians(10), 0.0), 'roll': (0.0, 0.0, math.radians(10))}


def turned(height, pitch, yaw, roll):
    return Camera(KINECT_640, height=height, pitch=pitch, yaw=yaw, roll=roll, frame_id='camera')


# Pitched down, the star's top arm ends 1-3 pixels below the image's top edge, within
# ``cut_margin_px`` once the dropout fill reads its rim: the thresholds take it for cut, the
# candidate scorer keeps it.
@pytest.mark.parametrize('turn, n', [
    pytest.param(turn, n, id=f'star{n}-{name}')
    for n in (4, 5) for name, turn in TURNS.items()])
def test_star_seen_by_a_turned_camera(turn, n):
    shot = _shoot('star', scenes.star(n, spin=1.0), turned(scenes.LEVEL.height, *turn))
    est = estimate_frame(shot.frame, EndeffParams())
    assert est.floor is None
    assert len(est.positions()) == n
    errors = tip_errors(shot.gt, est.positions())
    assert np.all(errors < TIP_TOLERANCE), np.round(errors, 3)


@pytest.mark.parametrize('x', [0.0, 0.2])
def test_chair_seen_by_a_camera_pitched_down(x):
    shot = _shoot('chair', scenes.placed_chair(0.5, x=x), turned(LOW.height, math.radians(10),
                                                                  0.0, 0.0))
    uv = KINECT_640.project(shot.gt)
    assert np.all((uv >= 0) & (uv < [640, 480]))  # premise: every end-effector is in view
    est = estimate_frame(shot.frame, EndeffParams())
    assert len(est.positions()) <= len(shot.gt)
    assert np.all(tip_errors(shot.gt[CHAIR_LEGS], est.positions()) < CHAIR_TOLERANCE)


# ---------------------------------------------------------------------------------------------
# Invariance (estimate_points on clouds: the well-posed path)
# ---------------------------------------------------------------------------------------------

INVARIANCE_SCENES = [
    pytest.param('star', 5, 0.3, id='star5'),
    pytest.param('person', 't_pose', 0.0, id='t_pose'),
    pytest.param('chair', 0.5, 0.0, id='chair'),
    pytest.param('arm', None, 0, id='robot_arm'),
]

#: Section 4 on an already downsampled cloud: no voxel grid (not rotation invariant) and no
#: floor fit (estimate_points never fits one).
CLOUD_PARAMS = EndeffParams(voxel_size=0.0, floor_removal=False)


@functools.cache
def foreground(kind, arg, variant):
    return foreground_cloud(rendered(kind, arg, variant).frame.depth, KINECT_640,
                            EndeffParams()).points


@pytest.mark.parametrize('kind, arg, variant', INVARIANCE_SCENES)
def test_point_order_does_not_matter(kind, arg, variant):
    points = foreground(kind, arg, variant)
    base = estimate_points(points, CLOUD_PARAMS)
    assert len(base.positions()) >= 2
    rng = np.random.default_rng(17)
    for _ in range(3):
        perm = rng.permutation(len(points))
        shuffled = estimate_points(points[perm], CLOUD_PARAMS)
        assert len(shuffled.positions()) == len(base.positions())
        assert set_distance(shuffled.positions(), base.positions()) < 1e-3
        np.testing.assert_allclose(shuffled.entities[0].root, base.entities[0].root, atol=1e-3)
        # Per-point labels follow the points.
        np.testing.assert_array_equal(shuffled.band, base.band[perm])


def _random_rotation(rng, max_angle):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return Rotation.from_rotvec(axis * rng.uniform(0.3, 1.0) * max_angle).as_matrix()


@pytest.mark.parametrize('kind, arg, variant', INVARIANCE_SCENES)
def test_camera_rotation_about_its_centre_rotates_the_tips(kind, arg, variant):
    """Turning the camera about its optical centre rotates the cloud and the viewing rays
    alike, so even the view-dependent part-radius step commutes with it (default params)."""
    points = foreground(kind, arg, variant)
    base = estimate_points(points, CLOUD_PARAMS).positions()
    rng = np.random.default_rng(23)
    for _ in range(3):
        rotation = _random_rotation(rng, math.radians(20))
        moved = estimate_points(points @ rotation.T, CLOUD_PARAMS).positions()
        assert set_distance(moved, base @ rotation.T) < 0.02


@pytest.mark.parametrize('kind, arg, variant', INVARIANCE_SCENES)
def test_rigid_motion_moves_the_tips(kind, arg, variant):
    """Rotation + translation. The part-radius step pushes a tip along the viewing ray from the
    camera origin, which a translation of the cloud does not carry along (measured up to
    2-3.4 cm on the robot arm), so the geometric part is tested with max_part_radius = 0."""
    params = CLOUD_PARAMS.replace(max_part_radius=0.0)
    points = foreground(kind, arg, variant)
    base = estimate_points(points, params).positions()
    rng = np.random.default_rng(29)
    for _ in range(3):
        rotation = _random_rotation(rng, math.radians(30))
        shift = rng.uniform(-0.5, 0.5, 3)
        moved = estimate_points(points @ rotation.T + shift, params).positions()
        assert set_distance(moved, base @ rotation.T + shift) < 0.02


# ---------------------------------------------------------------------------------------------
# Empty foreground
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize('fill', [np.nan, 0.0, 30.0, 10.0])  # 10 m: valid but outside the box
def test_empty_foreground_gives_no_entities(fill):
    depth = np.full((480, 640), fill, dtype=np.float32)
    est = estimate_frame(frame(depth), EndeffParams())
    assert est.entities == []
    assert est.positions().shape == (0, 3)
    assert len(est.points) == 0
    assert est.unreachable == 0


def test_empty_cloud_gives_no_entities():
    est = estimate_points(np.zeros((0, 3)), EndeffParams())
    assert est.entities == []
    assert est.positions().shape == (0, 3)


def test_small_clusters_are_not_entities():
    rng = np.random.default_rng(2)
    blob = rng.normal([0.0, 0.0, 2.0], 0.02, (20, 3))  # dense, but < min_entity_points
    est = estimate_points(blob, EndeffParams())
    assert est.entities == []
    assert np.all(est.entity == -1)
    assert np.all(est.band == UNREACHED)


# ---------------------------------------------------------------------------------------------
# Bands (Eqs. 1-4) on hand-made clouds
# ---------------------------------------------------------------------------------------------

def _line(n, spacing, start=(0.0, 0.0, 2.0), direction=(1.0, 0.0, 0.0)):
    return np.asarray(start) + np.arange(n)[:, None] * spacing * np.asarray(direction)


@pytest.mark.parametrize('delta', [0.05, 0.07, 0.1])
@pytest.mark.parametrize('seed_at', ['end', 'middle'])
def test_bands_advance_about_delta_per_band(delta, seed_at):
    spacing = 0.01
    points = _line(151, spacing)
    seed = 0 if seed_at == 'end' else 75
    graph = Neighbours.build(points, delta)
    dense = density_mask(graph, EndeffParams().band_eta)
    assert dense.all()
    band = expand_bands(graph, dense, np.array([seed]), delta)
    assert band[seed] == 0
    assert np.all(band >= 0)
    sides = [np.arange(seed, len(points))] + ([np.arange(seed, -1, -1)] if seed else [])
    for side in sides:  # the indices from the seed outwards
        reach = np.abs(points[side, 0] - points[seed, 0])
        labels = band[side]
        # Bands grow monotonically away from the seed.
        assert np.all(np.diff(labels) >= 0)
        farthest = np.array([reach[labels == k].max() for k in range(labels.max() + 1)])
        step = np.diff(farthest)[:-1]  # the last band is cut short by the end of the line
        # Each band reaches up to δ_L past the previous contour, which lies at most one
        # spacing (plus the ¾δ_L rim rule) inside the previous band's far edge.
        assert np.all(step <= delta + 1e-9), step
        assert np.all(step >= delta - 2 * spacing - 1e-9), step
        assert np.mean(step) == pytest.approx(delta, abs=spacing)
        assert labels.max() == pytest.approx(reach.max() / delta, abs=0.3 * reach.max() / delta)


def test_band_expansion_on_the_padded_table_equals_the_csr_rows():
    # A noisy branching cloud with sparse points: both neighbour layouts give the same bands.
    rng = np.random.default_rng(5)
    trunk = np.stack([np.zeros(80), np.linspace(0, 0.8, 80), np.full(80, 2.0)], 1)
    branch = np.stack([np.linspace(0, 0.5, 50), np.linspace(0.4, 0.1, 50), np.full(50, 2.0)], 1)
    cloud = np.concatenate([trunk, branch, rng.uniform(-0.3, 1.0, (40, 3)) + [0, 0, 2]])
    cloud += rng.normal(0, 0.004, cloud.shape)
    delta = 0.08
    padded = Neighbours.build(cloud, delta)
    rows = Neighbours.build(cloud, delta)
    rows.__dict__['padded'] = None  # what a graph too uneven to pad uses
    assert padded.padded is not None
    dense = density_mask(padded, 4)
    assert not dense.all()
    want = expand_bands(rows, dense, np.array([0]), delta)
    np.testing.assert_array_equal(expand_bands(padded, dense, np.array([0]), delta), want)
    assert want.max() >= 8


def test_sparse_points_are_not_banded():
    points = _line(100, 0.01)
    # Isolated points: a pair 2 cm apart far off the line, and a lone point.
    isolated = np.array([[0.5, 0.4, 2.0], [0.52, 0.4, 2.0], [1.5, 0.0, 2.0]])
    cloud = np.concatenate([points, isolated])
    eta, delta = EndeffParams().band_eta, EndeffParams().band_delta
    graph = Neighbours.build(cloud, delta)
    dense = density_mask(graph, eta)
    assert dense[:100].all()
    assert not dense[100:].any()  # fewer than η_L neighbours
    band = expand_bands(graph, dense, np.array([0]), delta)
    assert np.all(band[:100] >= 0)
    assert np.all(band[100:] == UNREACHED)
    # Also through the estimator: not banded, and the counter agrees with the labels.
    est = estimate_points(cloud, EndeffParams(min_entity_points=20))
    assert len(est.entities) == 1
    assert np.all(est.band[100:] == UNREACHED)
    assert np.all(est.band[:100] != UNREACHED)
    assert est.unreachable == np.count_nonzero((est.entity >= 0) & (est.band == UNREACHED))


def test_sparse_points_of_an_entity_are_counted_unreachable():
    points = _line(100, 0.01)
    stray = np.array([[0.99 + 0.055, 0.0, 2.0]])  # beyond the end: neighbours at 5.5, 6.5 cm
    cloud = np.concatenate([points, stray])
    params = EndeffParams(min_entity_points=20)
    graph = Neighbours.build(cloud, params.band_delta)
    assert density_mask(graph, params.band_eta)[-1] == np.False_  # premise: it is sparse
    assert graph.degree()[-1] >= 1  # ... and within δ_L of the entity
    est = estimate_points(cloud, params)
    assert est.band[-1] == UNREACHED
    assert est.unreachable >= 1


def test_leak_fallback_reaches_a_branch_joining_away_from_the_rim():
    """A line with points every 3 cm and δ_L = 7 cm: contours are the even points (the rim of
    each band is its point 6 cm out). A branch starts 6.6 cm beside an odd point: it is
    within δ_L of that band point but 7.25 cm from the contours on either side, so the front
    passes it by; only the leak fallback, once the front has died, can band it."""
    delta, spacing = 0.07, 0.03
    line = _line(21, spacing)  # x = 0 .. 0.6
    attach = line[11]  # x = 0.33, between the contours at 0.30 and 0.36
    branch = _line(10, spacing, start=attach + [0.0, 0.066, 0.0], direction=(0, 1, 0))
    points = np.concatenate([line, branch])
    graph = Neighbours.build(points, delta)
    dense = density_mask(graph, 2)
    assert dense.all()
    # Premise: the branch touches the line only at its attachment point.
    touching = np.linalg.norm(branch[:, None] - line[None], axis=2) < delta
    assert touching.sum() == 1 and touching[0, 11]
    band = expand_bands(graph, dense, np.array([0]), delta)
    line_band, branch_band = band[:21], band[21:]
    assert np.all(line_band >= 0)
    assert np.all(branch_band != UNREACHED)
    # Reached after the front along the line died: every branch band comes after the last
    # line band, and the branch is banded outwards from the attachment point.
    assert branch_band.min() > line_band.max()
    assert np.all(np.diff(branch_band) >= 0)


@pytest.mark.parametrize('counting_sort', [True, False])
def test_neighbours_are_every_pair_within_the_radius(monkeypatch, counting_sort):
    from endeff_ros.core import bands

    if not counting_sort:  # the argsort fallback gives the same structure
        monkeypatch.setattr(bands, '_coo_tocsr', None)
    rng = np.random.default_rng(3)
    points = rng.uniform(0, 0.4, (300, 3))
    radius = 0.06
    nb = Neighbours.build(points, radius)
    full = np.linalg.norm(points[:, None] - points[None], axis=2)
    want_i, want_j = np.nonzero(np.triu(full < radius, k=1))
    assert sorted(zip(nb.i.tolist(), nb.j.tolist())) == sorted(zip(want_i.tolist(),
                                                                   want_j.tolist()))
    assert np.all(np.diff(nb.i) >= 0)  # pairs sorted by i
    np.testing.assert_allclose(nb.d, full[nb.i, nb.j], rtol=1e-12)
    # The CSR adjacency is the symmetric matrix of the same pairs and distances.
    adjacency = sparse.csr_matrix((nb.data, nb.indices, nb.indptr), shape=(300, 300)).toarray()
    np.testing.assert_allclose(adjacency, np.where(full < radius, full, 0.0)
                               - np.diag(np.diag(full)), rtol=1e-12)
    np.testing.assert_array_equal(nb.degree(), (full < radius).sum(axis=1) - 1)


@pytest.mark.parametrize('kernel', [True, False])
def test_neighbours_components_are_the_connected_parts_of_the_kept_pairs(monkeypatch, kernel):
    from endeff_ros.core import bands

    if not kernel:  # scipy's public connected_components gives the same labels
        monkeypatch.setattr(bands, '_weak_components', None)
    elif bands._weak_components is None:
        pytest.skip("this scipy's weak-components kernel is missing or changed")
    rng = np.random.default_rng(5)
    points = rng.uniform(0, 0.5, (400, 3))
    nb = Neighbours.build(points, 0.06)
    keep = rng.random(len(nb.i)) < 0.5
    labels = nb.components(keep)
    # Reference: a union-find over the kept pairs.
    parent = list(range(nb.n))

    def find(a):
        while parent[a] != a:
            a = parent[a]
        return a

    for a, b in zip(nb.i[keep].tolist(), nb.j[keep].tolist()):
        parent[find(a)] = find(b)
    roots = np.array([find(a) for a in range(nb.n)])
    same = roots[:, None] == roots[None, :]
    np.testing.assert_array_equal(labels[:, None] == labels[None, :], same)
    assert 1 < len(np.unique(labels)) < nb.n  # premise: some parts joined, not all
    # Labels number the parts by their first point, as scipy's do.
    _, first = np.unique(labels, return_index=True)
    np.testing.assert_array_equal(labels[np.sort(first)], np.arange(len(first)))


def test_split_subbands_separates_parallel_lines_farther_than_connect():
    connect = 0.07
    x = np.arange(0, 0.5, 0.01)
    band_of = 1 + np.floor(x / 0.1).astype(int)
    for gap, separate in ((0.1, True), (0.04, False)):
        a = np.stack([x, np.zeros_like(x), np.full_like(x, 2.0)], 1)
        b = a + [0.0, gap, 0.0]
        points = np.concatenate([a, b])
        band = np.concatenate([band_of, band_of])
        graph = Neighbours.build(points, 0.12)
        sub = split_subbands(points, graph, band, connect=connect, max_points=1000)
        n_bands = len(np.unique(band_of))
        assert np.all(sub >= 0)
        # A sub-band never spans two bands.
        for s in np.unique(sub):
            assert len(np.unique(band[sub == s])) == 1
        if separate:
            assert len(np.unique(sub)) == 2 * n_bands
            assert not set(sub[: len(x)]) & set(sub[len(x):])
        else:
            assert len(np.unique(sub)) == n_bands
            np.testing.assert_array_equal(sub[: len(x)], sub[len(x):])


@pytest.mark.parametrize('n, max_points', [(200, 60), (61, 60), (60, 60), (500, 25)])
def test_split_subbands_caps_the_size(n, max_points):
    rng = np.random.default_rng(n)
    # One wide band: a strip 3 cm wide, a point every centimetre along x (no hole wider
    # than `connect`, so it is one connected piece before the cap).
    points = np.stack([np.arange(n) * 0.01, rng.uniform(0, 0.03, n), np.full(n, 2.0)], 1)
    band = np.ones(n, dtype=np.intp)
    graph = Neighbours.build(points, 0.07)
    sub = split_subbands(points, graph, band, connect=0.07, max_points=max_points)
    counts = np.bincount(sub)
    assert len(counts) == math.ceil(n / max_points)
    assert counts.max() <= max_points
    assert counts.sum() == n
    # Slices along the main axis (x): their x ranges do not overlap.
    ranges = sorted((points[sub == s, 0].min(), points[sub == s, 0].max())
                    for s in range(len(counts)))
    assert all(hi < lo for (_, hi), (lo, _) in zip(ranges[:-1], ranges[1:]))


def test_split_subbands_merges_slivers_and_skips_unreached():
    x = np.arange(0, 0.3, 0.01)
    points = np.stack([x, np.zeros_like(x), np.full_like(x, 2.0)], 1)
    band = np.where(x < 0.2, 1, 2)
    band[-3:] = UNREACHED
    band[19] = 3  # a one-point sliver of its own band
    graph = Neighbours.build(points, 0.07)
    plain = split_subbands(points, graph, band, connect=0.07, max_points=100)
    assert np.all(plain[-3:] == UNREACHED)
    assert len(np.unique(plain[plain >= 0])) == 3
    merged = split_subbands(points, graph, band, connect=0.07, max_points=100, min_points=2)
    assert np.all(merged[-3:] == UNREACHED)
    assert len(np.unique(merged[merged >= 0])) == 2
    assert merged[19] in (merged[18], merged[20])


# ---------------------------------------------------------------------------------------------
# Graph (Eqs. 5-7)
# ---------------------------------------------------------------------------------------------

def test_build_graph_weights_are_centroid_distances():
    rng = np.random.default_rng(4)
    # A bent tube: bands and sub-bands from the real expansion.
    t = np.linspace(0, 1, 400)
    axis = np.stack([t, 0.3 * np.sin(3 * t), np.full_like(t, 2.0)], 1)
    points = axis + rng.normal(0, 0.01, axis.shape)
    params = EndeffParams()
    graph = Neighbours.build(points, params.band_delta)
    dense = density_mask(graph, params.band_eta)
    band = expand_bands(graph, dense, np.array([0]), params.band_delta)
    band[0] = 1  # as estimate_points: the seed joins the first band
    sub = split_subbands(points, graph, band, connect=params.band_delta, max_points=60,
                         min_points=params.subband_min_points)
    g = build_graph(points, sub, band, graph, attach_distance=params.attach_distance,
                    attach_points=params.attach_points)
    k = sub.max() + 1
    assert g.n_nodes == k
    for s in range(k):
        np.testing.assert_allclose(g.centroids[s], points[sub == s].mean(0), atol=1e-12)
        assert g.sizes[s] == np.count_nonzero(sub == s)
        assert g.band[s] in band[sub == s]  # merged slivers may bring a neighbouring band
    rows, cols = g.weights.nonzero()
    assert len(rows) >= 2 * (k - 1)  # a tube is connected from end to end
    assert np.all(np.abs(g.band[rows] - g.band[cols]) <= 2)  # along the tube only
    for i, j in zip(rows, cols):
        assert g.weights[i, j] == pytest.approx(np.linalg.norm(g.centroids[i] - g.centroids[j]),
                                                abs=1e-12)
    assert (g.weights != g.weights.T).nnz == 0
    dist, _ = g.shortest_paths([sub[0]])
    assert np.all(np.isfinite(dist))


def _two_subbands(near_points, *, joined_by=False):
    """Sub-band A (a sparse row) and B (a tight cluster) where ``near_points`` points of A are
    within λ = 5 cm of B and all of B's points are within λ of A. With ``joined_by``, a third
    sub-band C (a dense row 4 cm beside A, reaching B) is attached to both, so A and B are in
    one graph piece whatever their own attachment."""
    a = [[x, 0.0, 2.0] for x in (0.0, 0.1, 0.2, 0.3)]
    a += [[0.5 - 0.01 * i, 0.0, 2.0] for i in range(near_points)]
    b = [[0.53, 0.0, 2.0], [0.535, 0.005, 2.0], [0.54, 0.0, 2.0], [0.535, -0.005, 2.0]]
    c = [[0.01 * i, 0.04, 2.0] for i in range(56)] if joined_by else []
    points = np.array(a + b + c)
    sub = np.array([0] * len(a) + [1] * len(b) + [2] * len(c))
    band = sub + 1
    return points, sub, band


@pytest.mark.parametrize('near_points, attach_points, attached', [
    (1, 2, False),  # only one point of A is near B: not attached with P = 2
    (1, 1, True),
    (2, 2, True),
    (2, 3, False),  # B has 4 near points but A only 2
])
def test_attachment_needs_p_points_on_both_sides(near_points, attach_points, attached):
    points, sub, band = _two_subbands(near_points, joined_by=True)
    graph = Neighbours.build(points, 0.06)
    g = build_graph(points, sub, band, graph, attach_distance=0.05,
                    attach_points=attach_points)
    assert g.weights[0, 2] > 0 and g.weights[1, 2] > 0  # premise: one piece through C
    assert (g.weights[0, 1] > 0) == attached
    assert (g.weights[1, 0] > 0) == attached


def test_pieces_the_expansion_connected_are_joined_once():
    """Without C, A and B are two pieces that attachment (P = 2) leaves apart, though a point
    of A is within δ_L of B (the band expansion crossed there): they are joined by one Eq. 5
    edge. Pieces with no neighbouring points stay apart."""
    points, sub, band = _two_subbands(1)
    g = build_graph(points, sub, band, Neighbours.build(points, 0.06), attach_distance=0.05,
                    attach_points=2)
    assert g.weights[0, 1] == pytest.approx(np.linalg.norm(g.centroids[0] - g.centroids[1]))
    far = points.copy()
    far[sub == 1] += [0.2, 0.0, 0.0]
    g = build_graph(far, sub, band, Neighbours.build(far, 0.06), attach_distance=0.05,
                    attach_points=2)
    assert g.weights[0, 1] == 0
    assert not np.isfinite(g.dist[0, 1])


def test_bridges_link_subbands_across_a_gap():
    points, sub, band = _two_subbands(1)
    points[sub == 1] += [0.2, 0.0, 0.0]  # no neighbouring points: only the bridge joins them
    graph = Neighbours.build(points, 0.06)
    g = build_graph(points, sub, band, graph, attach_distance=0.05, attach_points=2,
                    bridges=[(0, len(points) - 1)])
    assert g.weights[0, 1] == pytest.approx(np.linalg.norm(g.centroids[0] - g.centroids[1]))


def make_graph(centroids, edges):
    """A TopologyGraph over ``centroids`` with Eq. 5 weights on ``edges`` (i, j)."""
    centroids = np.asarray(centroids, float)
    k = len(centroids)
    i, j = (np.asarray(v, dtype=np.intp) for v in zip(*edges)) if edges else ([], [])
    w = np.linalg.norm(centroids[i] - centroids[j], axis=1)
    weights = sparse.csr_matrix((np.r_[w, w], (np.r_[i, j], np.r_[j, i])), shape=(k, k))
    dist, pred = csgraph.shortest_path(weights, method='D', directed=False,
                                       return_predecessors=True)
    return TopologyGraph(centroids, np.ones(k, dtype=np.intp), np.zeros(k, dtype=np.intp),
                         weights.toarray(), dist, pred)


def _limb(centroids, edges, start, direction, length, spacing=0.1):
    """Append to ``centroids`` and ``edges`` a straight limb from node ``start`` along
    ``direction``, ``length`` m long with a node every ``spacing`` m; returns its tip node."""
    prev = start
    direction = np.asarray(direction, float) / np.linalg.norm(direction)
    base = centroids[start]
    for step in range(1, int(round(length / spacing)) + 1):
        centroids.append(base + spacing * step * direction)
        edges.append((prev, len(centroids) - 1))
        prev = len(centroids) - 1
    return prev


def _y_graph():
    """Root at the junction, arms of 0.7, 0.6 and 0.5 m (nodes every 0.1 m) and a 0.2 m twig
    off the middle of the longest arm. Returns the graph and the leaf node of each arm."""
    centroids = [np.zeros(3)]
    edges = []
    leaves = {}
    for name, length, angle in (('a', 0.7, 90), ('b', 0.6, 210), ('c', 0.5, 330)):
        rad = math.radians(angle)
        leaves[name] = _limb(centroids, edges, 0, (math.cos(rad), math.sin(rad), 0), length)
    leaves['twig'] = _limb(centroids, edges, 3, (1, 0, 0), 0.2)  # node 3: 0.3 m up arm a
    return make_graph(centroids, edges), leaves


def test_find_end_effectors_on_a_y_graph():
    g, leaves = _y_graph()
    found = find_end_effectors(g, 0, min_geodesic=0.3, max_count=12)
    # The three leaves, farthest first; the 0.2 m twig is below g and stops the search.
    assert [node for node, _, _ in found] == [leaves['a'], leaves['b'], leaves['c']]
    for (node, path, protrusion), length in zip(found, (0.7, 0.6, 0.5)):
        assert path[0] == node and path[-1] == 0
        # Found from the root and the earlier paths (all meeting at the root): the full arm.
        assert protrusion == pytest.approx(length)
        assert geodesic(g, path) == pytest.approx(length)
        assert len(path) == round(length / 0.1) + 1


def _limb_with_slivers(tip_sizes):
    """A root and one straight 0.6 m limb (nodes every 0.1 m, 10 points each) that runs on
    0.2 m and 0.23 m past its last node through two more nodes of ``tip_sizes`` points (a
    surface seen edge-on). Returns the graph, the limb's last node and the outermost node."""
    centroids, edges = [np.zeros(3)], []
    last = _limb(centroids, edges, 0, (0, 1, 0), 0.6)
    centroids.append(centroids[last] + [0.0, 0.2, 0.0])
    edges.append((last, len(centroids) - 1))
    centroids.append(centroids[-1] + [0.0, 0.03, 0.0])
    edges.append((len(centroids) - 2, len(centroids) - 1))
    g = make_graph(centroids, edges)
    sizes = np.full(len(centroids), 10, dtype=np.intp)
    sizes[-2:] = tip_sizes
    return dataclasses.replace(g, sizes=sizes), last, len(centroids) - 1


@pytest.mark.parametrize('tip_sizes, moved', [((1, 2), True), ((2, 3), True),
                                              ((3, 3), False), ((1, 6), False)])
def test_an_end_that_is_a_sliver_moves_back_to_its_part(tip_sizes, moved):
    g, last, outer = _limb_with_slivers(tip_sizes)
    extremes = []
    found = find_end_effectors(g, 0, min_geodesic=0.3, max_count=12, tip_depth=0.14,
                               min_tip_points=6, extremes=extremes)
    node, path, protrusion = found[0]
    # The extreme decides g and is reported as such; the end is the limb's last node when
    # the two outer nodes (both within tip_depth of the outermost) hold fewer than 6 points.
    assert extremes[0] == outer
    assert protrusion == pytest.approx(0.83)
    assert node == (last if moved else outer)
    assert path[0] == node and path[-1] == 0
    # Off (the default of the function): the extreme.
    assert find_end_effectors(g, 0, min_geodesic=0.3, max_count=12)[0][0] == outer


def test_a_branch_of_slivers_keeps_its_extreme():
    """Walking back would reach the root (the target set): the end stays where it is."""
    centroids, edges = [np.zeros(3)], []
    _limb(centroids, edges, 0, (0, 1, 0), 0.5)
    g = make_graph(centroids, edges)
    g = dataclasses.replace(g, sizes=np.r_[10, np.ones(len(centroids) - 1, dtype=np.intp)])
    extremes = []
    found = find_end_effectors(g, 0, min_geodesic=0.3, max_count=12, tip_depth=0.14,
                               min_tip_points=6, extremes=extremes)
    assert [f[0] for f in found] == extremes == [len(centroids) - 1]


def test_a_sliver_on_the_image_border_cuts_the_end_moved_back_from_it():
    """drop_cut_ends checks the sliver an end was moved back from, not only its node."""
    from endeff_ros.core.single_frame import EntityEstimate, FrameEstimate, drop_cut_ends
    from endeff_ros.core.types import Candidate

    # Two points: node 0 in the middle of the image, node 1 on its left border.
    points = np.array([[0.0, 0.0, 2.0], [-1.3, 0.0, 2.0]])
    subband = np.array([0, 1])
    params = EndeffParams(**RULES)

    def estimate(extreme):
        c = Candidate(position=points[0], node=0, geodesic=1.0, geodesic_approx=1.0,
                      path=points[:1], extreme=extreme)
        e = EntityEstimate(entity=0, root=points[0], candidates=[c], graph=None,
                           point_index=np.arange(2))
        return FrameEstimate(points=points, band=np.zeros(2, np.intp), subband=subband,
                             entity=np.zeros(2, np.intp), entities=[e], unreachable=0)

    u = KINECT_640.fx * points[1, 0] / points[1, 2] + KINECT_640.cx
    assert u < params.cut_margin_px  # premise: node 1 is on the border
    assert len(drop_cut_ends(estimate(None), KINECT_640, params).entities[0].candidates) == 1
    assert len(drop_cut_ends(estimate(1), KINECT_640, params).entities[0].candidates) == 0


@pytest.mark.parametrize('min_geodesic, max_count, expected', [
    (0.55, 12, ['a', 'b']),         # c (0.5 m from the found paths) is below g
    (0.15, 12, ['a', 'b', 'c', 'twig']),
    (0.3, 2, ['a', 'b']),           # capped
    (0.8, 12, []),
])
def test_find_end_effectors_stops_below_g(min_geodesic, max_count, expected):
    g, leaves = _y_graph()
    found = find_end_effectors(g, 0, min_geodesic=min_geodesic, max_count=max_count)
    assert [node for node, _, _ in found] == [leaves[name] for name in expected]
    # Every protrusion (distance to the target set when found) is at least g, decreasing.
    protrusions = [p for _, _, p in found]
    assert all(p >= min_geodesic for p in protrusions)
    assert protrusions == sorted(protrusions, reverse=True)
    if 'twig' in expected:
        assert protrusions[-1] == pytest.approx(0.2)  # from the middle of arm a


def _edges(g):
    """The (i, j) node pairs joined by an edge of ``g``, each once."""
    return list(zip(*np.triu(g.dense_weights).nonzero()))


def _chain_graph(twig_nodes):
    """The Y graph's arms a, b, c plus a 0.27 m twig off the root made of ``twig_nodes`` edges:
    a chain of short edges (a limb crossing bands) or one long edge (a large sub-band)."""
    g, leaves = _y_graph()
    centroids = list(g.centroids)
    edges = _edges(g)
    prev = 0
    for step in range(1, twig_nodes + 1):
        centroids.append(np.array([0.0, 0.0, 0.27 * step / twig_nodes]))
        edges.append((prev, len(centroids) - 1))
        prev = len(centroids) - 1
    leaves['twig'] = prev
    return make_graph(centroids, edges), leaves


@pytest.mark.parametrize('twig_nodes, chain_geodesic, chain_subbands, found_twig', [
    (3, 0.25, 3, True),    # 0.27 m in 3 edges: a chain below g, found
    (1, 0.25, 3, False),   # 0.27 m in one edge: not a chain
    (2, 0.25, 3, False),
    (3, 0.25, 4, False),   # a longer chain asked for
    (3, 0.28, 3, False),   # below the chain threshold
    (3, None, 3, False),   # the paper's rule: g alone
    (3, 0.3, 3, False),    # chain threshold at g: g alone
])
def test_chains_below_g(twig_nodes, chain_geodesic, chain_subbands, found_twig):
    g, leaves = _chain_graph(twig_nodes)
    found = find_end_effectors(g, 0, min_geodesic=0.3, max_count=12,
                               chain_geodesic=chain_geodesic, chain_subbands=chain_subbands)
    nodes = [node for node, _, _ in found]
    assert nodes[:3] == [leaves['a'], leaves['b'], leaves['c']]
    assert nodes[3:] == ([leaves['twig']] if found_twig else [])
    if found_twig:
        assert found[3][2] == pytest.approx(0.27)


def test_a_failed_chain_is_passed_over_for_a_farther_chain():
    """Two twigs below g off the root: 0.29 m in one edge (no chain) and 0.26 m in 3 edges.
    The first is the farthest node but is passed over (and does not become a target); the
    chain is found."""
    g, leaves = _chain_graph(3)
    centroids = list(g.centroids) + [np.array([0.0, 0.0, -0.29])]
    g = make_graph(centroids, [*_edges(g), (0, len(centroids) - 1)])
    found = find_end_effectors(g, 0, min_geodesic=0.3, max_count=12, chain_geodesic=0.25)
    assert [node for node, _, _ in found][3:] == [leaves['twig']]


def test_a_chain_end_is_a_local_maximum_of_the_root_distance():
    """The twig's end linked (by a 0.57 m edge) to arm a 0.5 m from the root: still 0.27 m
    from the found paths, but a neighbour lies farther from the root, so it is a point between
    paths, not an end."""
    g, leaves = _chain_graph(3)
    arm_a = 5  # node 5 is 0.5 m up arm a
    assert np.allclose(g.centroids[arm_a], [0.0, 0.5, 0.0], atol=1e-9)
    g = make_graph(g.centroids, [*_edges(g), (leaves['twig'], arm_a)])
    found = find_end_effectors(g, 0, min_geodesic=0.3, max_count=12, chain_geodesic=0.25)
    assert leaves['twig'] not in [node for node, _, _ in found]


@pytest.mark.parametrize('min_points, found_twig', [(1, True), (2, False)])
def test_a_chain_ends_in_a_full_sub_band(min_points, found_twig):
    g, leaves = _chain_graph(3)  # every node of the test graph holds one point
    found = find_end_effectors(g, 0, min_geodesic=0.3, max_count=12, chain_geodesic=0.25,
                               chain_min_points=min_points)
    assert (leaves['twig'] in [node for node, _, _ in found]) == found_twig


def _loop_graph():
    """A 2 m loop through the root (down the sides x = -0.2 and 0.2 m, 0.6 m high, across the
    top) and a 0.45 m leaf below the root, nodes every 0.1 m. Returns the graph and the nodes
    of the loop's top middle and of the leaf's tip."""
    pts = [(0.0, 0.0)]
    pts += [(-0.1, 0.0), (-0.2, 0.0)] + [(-0.2, 0.1 * k) for k in range(1, 7)]
    pts += [(-0.1, 0.6), (0.0, 0.6), (0.1, 0.6), (0.2, 0.6)]
    pts += [(0.2, 0.1 * k) for k in range(5, -1, -1)] + [(0.1, 0.0)]
    loop = list(range(len(pts)))
    edges = list(zip(loop, loop[1:] + [0]))
    leaf = [len(pts) + k for k in range(5)]
    pts += [(0.0, -0.1 * k) for k in range(1, 5)] + [(0.0, -0.45)]
    edges += list(zip([0] + leaf[:-1], leaf))
    centroids = [(x, y, 0.0) for x, y in pts]
    return make_graph(centroids, edges), pts.index((0.0, 0.6)), leaf[-1]


def test_the_far_side_of_a_loop_is_flagged():
    """The loop's top is its farthest point from the root and the first end-effector; its
    path runs down one side, and the other side's middle, 0.5 m from the top and from the
    root along that side, is the next extreme: it ends no chain (its two neighbours reach
    the found path at points 1 m apart), while the leaf ends one."""
    g, top, tip = _loop_graph()
    sides: list[bool] = []
    found = find_end_effectors(g, 0, min_geodesic=0.3, max_count=12, loop_sides=sides)
    nodes = [node for node, _, _ in found]
    assert nodes[0] == top and tip in nodes and len(nodes) == 3
    far = nodes[1]
    assert np.allclose(np.abs(g.centroids[far]), [0.2, 0.3, 0.0])
    assert found[1][2] == pytest.approx(0.5)
    assert sides == [False, True, False]
    # Without the question nothing changes.
    assert [node for node, _, _ in find_end_effectors(g, 0, min_geodesic=0.3,
                                                      max_count=12)] == nodes


@pytest.mark.parametrize('arm', ['folded', 'clasped'])
def test_the_elbow_of_a_closed_arm_is_no_end(arm):
    """Arms folded on the chest, or hands clasped in front of it: the elbow on the far side of
    the loop the arms close was an extreme 0.23-0.35 m from every labelled end; it is kept
    apart (``loop_sides``) and every reported end lies on a labelled one."""
    pose = sc.ARM_FOLDED if arm == 'folded' else sc.clap_arm(0.0)
    shot = scenes.shoot(sc.person(pose), scenes.LEVEL, floor=True)

    def farthest(positions):
        return max(float(np.linalg.norm(shot.gt[:, :3] - p, axis=1).min()) for p in positions)

    before = estimate_frame(shot.frame, EndeffParams(loop_far_sides=False))
    assert farthest(before.positions()) > 0.2  # premise: the elbow was reported
    est = estimate_frame(shot.frame, EndeffParams())
    assert farthest(est.positions()) < 0.1
    sides = [c.position for e in est.entities for c in e.loop_sides]
    assert sides and farthest(sides) > 0.2
    assert len(est.positions()) == len(before.positions()) - len(sides)


@functools.cache
def short_person_pose(pose, scale):
    """A person in ``pose`` ``scale`` times the 1.75 m model."""
    return scenes.shoot(scenes.person(pose, model=PersonModel(PersonStyle(scale=scale))))


def short_person(scale):
    """A T-pose person ``scale`` times the 1.75 m model (its head protrudes less)."""
    return short_person_pose('t_pose', scale)


def test_t_pose_head_is_found_as_a_chain_below_g():
    """A T-pose person's head can protrude less than g from the hands' paths (they cross the
    top of the torso): for a 1.49 m person (scale 0.85) by 0.258 m (the 1.75 m model's head:
    0.353 m, found by g alone). The chain rule finds it, g alone does not."""
    shot = short_person(0.85)
    chains = estimate_frame(shot.frame, EndeffParams(**RULES))
    paper = estimate_frame(shot.frame, EndeffParams(**RULES, chain_geodesic=0.3))
    head = shot.gt[HEAD]
    assert tip_errors(head[None], chains.positions())[0] < TIP_TOLERANCE
    assert tip_errors(head[None], paper.positions())[0] > 0.15
    (candidate,) = [c for c in chains.entities[0].candidates
                    if np.linalg.norm(c.position - head) < TIP_TOLERANCE]
    params = EndeffParams(**RULES)
    assert params.chain_geodesic <= candidate.protrusion < params.min_geodesic


def test_t_pose_head_of_a_shorter_person():
    """A 1.58 m person's T-pose head protrudes 0.232 m from the hands' paths: a chain below
    g, found down to chain_geodesic (0.2 m), and not with a chain threshold above it."""
    shot = short_person(0.9)
    est = estimate_frame(shot.frame, EndeffParams(**RULES))
    assert tip_errors(shot.gt[HEAD][None], est.positions())[0] < TIP_TOLERANCE
    higher = estimate_frame(shot.frame, EndeffParams(**RULES, chain_geodesic=0.25))
    assert tip_errors(shot.gt[HEAD][None], higher.positions())[0] > 0.15


def _two_limbs(long: float, short: float):
    """A root with a limb of ``long`` m and one of ``short`` m on the other side (nodes every
    0.05 m); returns the graph and the short limb's end node."""
    centroids = [np.zeros(3)]
    edges = []
    _limb(centroids, edges, 0, (1, 0, 0), long, spacing=0.05)
    end = _limb(centroids, edges, 0, (-1, 0, 0), short, spacing=0.05)
    return make_graph(centroids, edges), end


@pytest.mark.parametrize('long, short, scale_length, found', [
    (0.6, 0.25, 0.9, True),    # g shrinks to 0.3 * 0.6 / 0.9 = 0.2 m: the 0.25 m limb is an end
    (0.6, 0.25, 0.0, False),   # off: g alone, as the paper
    (0.9, 0.25, 0.9, False),   # an adult-sized entity keeps g
    (0.6, 0.15, 0.9, False),   # below the shrunk g
    (0.3, 0.15, 0.9, False),   # shrunk at most to scale_min (0.6): g 0.18 m, not 0.1 m
])
def test_relative_thresholds_shrink_g_for_a_small_entity(long, short, scale_length, found):
    """g and the chain threshold shrink with the first end's geodesic distance below
    scale_length, down to scale_min of their values."""
    g, end = _two_limbs(long, short)
    ends = find_end_effectors(g, 0, min_geodesic=0.3, max_count=12, scale_length=scale_length,
                              scale_min=0.6)
    assert (end in [node for node, _, _ in ends]) == found


def test_a_small_childs_hand_is_found_with_relative_thresholds():
    """A 1.05 m child (the 1.75 m model at 0.6), arms hanging: one hand ends a limb that
    protrudes less than g = 0.3 m from the root and the other paths; with g relative to the
    child's size it is found, with g in metres alone it is not; no end is added elsewhere."""
    shot = short_person_pose('arms_down', 0.6)
    params = EndeffParams(**RULES, background=False)
    relative = estimate_frame(shot.frame, params)
    metres = estimate_frame(shot.frame, dataclasses.replace(params, scale_length=0.0))
    hand = shot.gt[LEFT_HAND][None]
    assert tip_errors(hand, relative.positions())[0] < TIP_TOLERANCE
    assert tip_errors(hand, metres.positions())[0] > 0.15
    assert len(relative.positions()) == len(metres.positions()) + 1


def test_geodesics_eqs_6_and_7():
    g, leaves = _y_graph()
    found = {node: path for node, path, _ in find_end_effectors(g, 0, min_geodesic=0.3,
                                                                max_count=12)}
    root = g.centroids[0]
    for name, length in (('a', 0.7), ('b', 0.6), ('c', 0.5)):
        path = found[leaves[name]]
        assert geodesic(g, path) == pytest.approx(length)  # Eq. 6
        position = g.centroids[leaves[name]] + [0.0, 0.0, 0.05]
        mid = g.centroids[path[len(path) // 2]]
        expected = np.linalg.norm(position - mid) + np.linalg.norm(mid - root)  # Eq. 7
        assert approximate_geodesic(position, g, path, root) == pytest.approx(expected)
    # On a straight path Eq. 7 equals the path length.
    path = found[leaves['a']]
    assert approximate_geodesic(g.centroids[path[0]], g, path, root) == pytest.approx(0.7)


def test_approximate_geodesic_uses_the_middle_node_by_count():
    centroids = np.array([[0.0, 0, 0], [0.3, 0, 0], [0.3, 0.4, 0], [0.3, 0.9, 0]])
    g = make_graph(centroids, [(0, 1), (1, 2), (2, 3)])
    path = np.array([3, 2, 1, 0])  # mid = path[2] = node 1
    e = np.array([0.3, 1.0, 0.0])
    assert approximate_geodesic(e, g, path, centroids[0]) == pytest.approx(1.0 + 0.3)


def test_distance_to_path_is_to_the_nearest_segment():
    """The distance from a point to a path given by its node positions (the polyline, not
    its nodes): what case B asks of a candidate and a track's memorised path."""
    path = np.array([[0.3, 1.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert distance_to_path(np.array([0.5, 0.5, 0.0]), path) == pytest.approx(0.2)
    assert distance_to_path(np.array([0.15, -0.1, 0.0]), path) == pytest.approx(0.1)
    assert distance_to_path(np.array([0.3, 1.2, 0.0]), path) == pytest.approx(0.2)  # beyond
    assert distance_to_path(np.array([1.0, 0.0, 0.0]), path[:1]) == pytest.approx(
        np.hypot(0.7, 1.0))
    assert distance_to_path(np.zeros(3), np.zeros((0, 3))) == np.inf


def test_candidates_carry_consistent_geodesics():
    est, _ = estimated('star', 5, 0.3)
    entity = est.entities[0]
    g = entity.graph
    for c in entity.candidates:
        assert c.path.shape[1] == 3
        np.testing.assert_allclose(c.path[0], g.centroids[c.node])
        assert c.geodesic == pytest.approx(np.linalg.norm(np.diff(c.path, axis=0), axis=1).sum())
        mid = c.path[len(c.path) // 2]
        assert c.geodesic_approx == pytest.approx(
            np.linalg.norm(c.end_centre - mid) + np.linalg.norm(mid - entity.root))
        # Eq. 6 is at least the straight line from the end-effector node to the root node,
        # and at least the lowest protrusion accepted (g, or the chain threshold below it).
        assert c.geodesic >= np.linalg.norm(c.path[0] - c.path[-1]) - 1e-9
        assert c.geodesic >= c.protrusion - 1e-9
        assert c.protrusion >= EndeffParams().chain_geodesic


def test_an_end_cut_by_the_image_border_is_no_end_effector():
    """A star pushed to the right so that one limb leaves the image: the limb's stump at the
    border is where the view cuts the body, not an end; the other limbs' tips are found."""
    shot = rendered('star', 5, 0.3)
    depth, tips = shot.frame.depth, shot.gt
    # Pixels: the limb pointing right (limb 0, 0.3 rad off horizontal) leaves the image, the
    # one pointing down and right (limb 4) ends 20 px inside it.
    shift = 220
    moved = np.full_like(depth, np.nan)
    moved[:, shift:] = depth[:, :-shift]
    z = tips[:, 2]
    tips = tips + np.stack([shift * z / KINECT_640.fx, 0 * z, 0 * z], axis=1)
    inside = KINECT_640.project(tips)[:, 0] < KINECT_640.width - 10
    assert inside.sum() == 4  # premise: exactly one tip left the image
    kept = estimate_frame(frame(moved), EndeffParams(**RULES)).positions()
    kept_all = estimate_frame(frame(moved),
                              EndeffParams(**RULES, drop_cut_ends=False)).positions()
    dropped = [p for p in kept_all if not any(np.allclose(p, q) for q in kept)]
    assert len(dropped) == 1 and len(kept) == len(kept_all) - 1
    # The stump: at the border (its sub-band spans the 0.09 m thick limb, 19 px at 2.5 m, so
    # the centroid lies up to about 10 px plus the part-radius step inside it), and no tip.
    assert KINECT_640.project(dropped[0][None])[0, 0] > KINECT_640.width - 20
    assert np.linalg.norm(tips[inside] - dropped[0], axis=1).min() > 0.15
    rows, cols, dist = match(tips[inside], kept)
    assert len(rows) == 4 and np.all(dist < 0.05), dist


def _patch(centre, size=0.2, spacing=0.03, tilt_deg=0.0):
    """A square grid of points facing the camera (z), turned ``tilt_deg`` about y."""
    g = np.arange(-size / 2, size / 2 + 1e-9, spacing)
    u, v = np.meshgrid(g, g)
    t = np.deg2rad(tilt_deg)
    pts = np.stack([u.ravel() * np.cos(t), v.ravel(), u.ravel() * np.sin(t)], 1)
    return pts + np.asarray(centre)


def test_steep_steps_cut_a_surface_in_front_of_another():
    """A hand 5 cm in front of the chest: every neighbour pair across the step that lies
    more than 3 times farther apart along the ray than across it is dropped, every pair
    within either surface kept; off (ratio 0) nothing is dropped."""
    chest = _patch((0.0, 0.0, 2.0), size=0.4)
    hand = _patch((0.0, 0.0, 1.95), size=0.1)
    cloud = np.concatenate([chest, hand])
    on_hand = np.r_[np.zeros(len(chest), bool), np.ones(len(hand), bool)]
    full = Neighbours.build(cloud, 0.08)
    across = on_hand[full.i] != on_hand[full.j]
    assert across.any()
    cut = Neighbours.build(cloud, 0.08, steep_ratio=3.0, steep_min=0.04)
    kept = {(int(a), int(b)) for a, b in zip(cut.i, cut.j)}
    pairs = list(zip(full.i.tolist(), full.j.tolist()))
    # Pairs across the step that are more behind each other than beside each other go.
    for (a, b), x in zip(pairs, across):
        rel = cloud[b] - cloud[a]
        lateral = np.hypot(rel[0], rel[1])
        if x and abs(rel[2]) > 3.0 * lateral:
            assert (a, b) not in kept
        if not x:
            assert (a, b) in kept
    assert len(cut.i) < len(full.i)
    off = Neighbours.build(cloud, 0.08, steep_ratio=0.0, steep_min=0.04)
    assert len(off.i) == len(full.i)


@pytest.mark.parametrize('tilt', [0.0, 45.0, 65.0])
def test_steep_steps_keep_a_surface_seen_obliquely(tilt):
    """A single surface turned up to 65 degrees from head-on (neighbours up to tan 65 = 2.1
    times farther apart along the ray than across it) keeps all its pairs at ratio 3."""
    plane = _patch((0.0, 0.0, 2.0), size=0.4, tilt_deg=tilt)
    full = Neighbours.build(plane, 0.08)
    assert len(Neighbours.build(plane, 0.08, steep_ratio=3.0, steep_min=0.04).i) == len(full.i)


@pytest.mark.parametrize('off_axis', [0.0, 60.0])
def test_steep_steps_follow_the_viewing_ray_not_the_optical_axis(off_axis):
    """A hand 6 cm in front of the chest along the viewing ray, both facing the camera, seen
    on the optical axis or 60 degrees off it: the pair from each hand point to the chest
    point straight behind it is cut, no pair within either surface is. Off the axis that
    step is only 3 cm in z, under ``steep_min``: a rule on z alone would keep it."""
    t = np.deg2rad(off_axis)
    ray = np.array([np.sin(t), 0.0, np.cos(t)])
    across_u, across_v = np.array([np.cos(t), 0.0, -np.sin(t)]), np.array([0.0, 1.0, 0.0])
    g = np.arange(-0.15, 0.15 + 1e-9, 0.03)
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    chest = 2.0 * ray + u[:, None] * across_u + v[:, None] * across_v
    small = (np.abs(u) <= 0.045) & (np.abs(v) <= 0.045)
    # The hand's points lie on the rays through the chest points they hide.
    hand = chest[small] * (1.0 - 0.06 / 2.0)
    cloud = np.concatenate([chest, hand])
    on_hand = np.r_[np.zeros(len(chest), bool), np.ones(len(hand), bool)]
    cut = Neighbours.build(cloud, 0.08, steep_ratio=4.0, steep_min=0.04)
    full = Neighbours.build(cloud, 0.08)
    kept = set(zip(cut.i.tolist(), cut.j.tolist()))
    behind = np.flatnonzero(small)
    for k, b in enumerate(behind):
        assert (int(b), len(chest) + k) not in kept
    same = on_hand[full.i] == on_hand[full.j]
    assert all(p in kept for p in zip(full.i[same].tolist(), full.j[same].tolist()))


def test_estimator_cuts_steep_steps_with_its_parameters(monkeypatch):
    """``estimate_points`` hands ``steep_step_ratio`` and ``steep_step_min`` to the cut, and
    the graph it builds is the full graph less exactly the pairs the cut names: some of those
    straight through a hand 6 cm in front of the chest, none elsewhere."""
    chest = _patch((0.0, 0.0, 2.0), size=0.6)
    hand = _patch((0.0, 0.06, 1.94), size=0.12)
    cloud = np.concatenate([chest, hand])
    on_hand = np.r_[np.zeros(len(chest), bool), np.ones(len(hand), bool)]
    seen, built = [], []
    original_cut, original_build = bands.steep_pairs, Neighbours.build.__func__

    def spy_cut(points, i, j, d, ratio, min_step):
        out = original_cut(points, i, j, d, ratio, min_step)
        seen.append((ratio, min_step))
        return out

    def spy_build(cls, *args, **kwargs):
        out = original_build(cls, *args, **kwargs)
        built.append(out)
        return out

    monkeypatch.setattr(bands, 'steep_pairs', spy_cut)
    monkeypatch.setattr(Neighbours, 'build', classmethod(spy_build))
    params = dataclasses.replace(EndeffParams(), steep_step_ratio=3.0, steep_step_min=0.05,
                                 min_entity_points=10)
    estimate_points(cloud, params)
    assert seen == [(3.0, 0.05)]
    cut = built[0]
    full = original_build(Neighbours, cloud, 0.08)
    joined_before = np.count_nonzero(on_hand[full.i] != on_hand[full.j])
    joined_after = np.count_nonzero(on_hand[cut.i] != on_hand[cut.j])
    assert 0 < joined_after < joined_before
    assert len(cut.i) == len(full.i) - (joined_before - joined_after)


SHIRT, SKIN = (40.0, 80.0, 100.0), (150.0, 115.0, 90.0)


def _hand_on_belly(hand_color=SKIN):
    """A belly facing the camera at 2 m, half of it patterned (another colour at the same
    depth), and a hand lying on it 2.5 cm nearer; (cloud, colours, on_hand)."""
    chest = _patch((0.0, 0.0, 2.0), size=0.4)
    hand = _patch((0.0, 0.0, 1.975), size=0.1)
    cloud = np.concatenate([chest, hand])
    colors = np.array([SHIRT] * len(chest) + [hand_color] * len(hand))
    colors[:len(chest)][chest[:, 0] > 0.1] = (200.0, 40.0, 40.0)  # the pattern
    on_hand = np.r_[np.zeros(len(chest), bool), np.ones(len(hand), bool)]
    return cloud, colors, on_hand


def test_colour_edges_cut_a_hand_lying_on_the_belly():
    """Every pair between the hand and the belly behind or beside it (ranges 2.5 cm apart,
    colours far apart) is cut, whatever its direction; the pattern's edge on the belly (no
    step) and the hand's own pairs stay; a hand of the shirt's colour, or the rule off,
    keeps every pair."""
    cloud, colors, on_hand = _hand_on_belly()
    full = Neighbours.build(cloud, 0.08)
    across = on_hand[full.i] != on_hand[full.j]
    cut = Neighbours.build(cloud, 0.08, colors=colors, color_rgb=35.0, color_step=0.015)
    kept = set(zip(cut.i.tolist(), cut.j.tolist()))
    for a, b, x in zip(full.i.tolist(), full.j.tolist(), across):
        assert ((a, b) in kept) != bool(x)
    patterned = (colors[full.i] != colors[full.j]).any(axis=1) & ~across
    assert patterned.any()  # the pattern's edge is there, and kept (checked above)
    same, _, _ = _hand_on_belly(hand_color=SHIRT)
    shirt = np.array([SHIRT] * len(same))
    assert len(Neighbours.build(same, 0.08, colors=shirt, color_rgb=35.0,
                                color_step=0.015).i) == len(Neighbours.build(same, 0.08).i)
    assert len(Neighbours.build(cloud, 0.08, colors=colors, color_rgb=0.0,
                                color_step=0.015).i) == len(full.i)
    # A step under color_step is no edge: the hand 1 cm nearer keeps its pairs.
    assert bands.color_edge_pairs(cloud, colors, full.i, full.j, 35.0, 0.03).sum() == 0


def test_estimator_cuts_colour_edges_with_its_parameters(monkeypatch):
    """``estimate_points`` hands the colours, ``color_edge_rgb`` and ``color_edge_step`` to
    the cut; without colours (a depth-only stream) there is nothing to cut."""
    cloud, colors, on_hand = _hand_on_belly()
    asked = []
    original = bands.color_edge_pairs

    def spy(points, cols, i, j, rgb, min_step):
        asked.append((cols is colors, rgb, min_step))
        return original(points, cols, i, j, rgb, min_step)

    monkeypatch.setattr(bands, 'color_edge_pairs', spy)
    params = dataclasses.replace(EndeffParams(), color_edge_rgb=50.0, color_edge_step=0.02,
                                 min_entity_points=10)
    estimate_points(cloud, params, colors=colors)
    assert asked == [(True, 50.0, 0.02)]
    estimate_points(cloud, params)
    estimate_points(cloud, dataclasses.replace(params, color_edge_rgb=0.0), colors=colors)
    assert len(asked) == 1
