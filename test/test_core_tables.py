"""Level surfaces above the floor that cover a table's area (table tops, desks) are dropped
with the floor (:func:`endeff_ros.core.surfaces.level_surface_points`); a body, a chair's seat and
upright things cut by a level slab are not. What a dropped top hides ends beside it, and that
end is a cut (:func:`endeff_ros.core.surfaces.beside_dropped`), no end-effector."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from endeff_ros.core.background import BackgroundModel
from endeff_ros.core.cloud import foreground_cloud
from endeff_ros.core.params import EndeffParams
from endeff_ros.core.single_frame import estimate_frame
from endeff_ros.core.types import KINECT_640, RGBDFrame
from endeff_ros.synth import room, scenes
from endeff_ros.synth.body import Entity, merge
from endeff_ros.synth.render import Camera

#: A camera 1.6 m up, pitched down 20 degrees: it sees the top of a table 2 m away.
HIGH = Camera(KINECT_640, height=1.6, pitch=np.deg2rad(20.0), frame_id='camera')
#: No background model: one frame, every part of the box is foreground but for the rules.
PARAMS = EndeffParams(background=False)
TOP = 0.74  # the table top's height (room.table)


def shot(*entities: Entity) -> scenes.Shot:
    return scenes.shoot(merge(list(entities)), HIGH)


def scene(points: np.ndarray) -> np.ndarray:
    """Optical-frame points seen by HIGH in the scene frame (y up from the floor)."""
    return points @ HIGH.rotation + [0.0, HIGH.height, 0.0]


def in_table(points: np.ndarray, z: float = -2.2) -> np.ndarray:
    """Whether each point lies within the table's extent (room.table's 1.2 x 0.7 m)."""
    p = scene(points)
    return (np.abs(p[:, 0]) < 0.65) & (np.abs(p[:, 2] - z) < 0.4) & (p[:, 1] < TOP + 0.02)


def on_top(points: np.ndarray, top: float = TOP) -> int:
    """Points of the table's extent at its top's height."""
    return int(np.count_nonzero(in_table(points) & (np.abs(scene(points)[:, 1] - top) < 0.02)))


def cloud(frame: RGBDFrame, **kw: float) -> np.ndarray:
    return foreground_cloud(frame.depth, frame.intrinsics, PARAMS.replace(**kw)).points


def table(x: float = 0.0, z: float = -2.2, **kw: float) -> Entity:
    return room.background_entity(room.table(x, z, **kw))


def test_a_table_in_front_of_a_person_is_dropped_and_the_person_kept() -> None:
    person = scenes.person('arms_down', z=-2.8)
    with_table = shot(person, table()).frame
    points, without = cloud(with_table), cloud(with_table, table_min_area=0.0)
    assert on_top(without) > 1000  # the top, without the rule
    assert on_top(points) == 0
    # Every point above the table's level stays (head, torso, arms).
    above = scene(without)[:, 1] > TOP + 0.1
    assert np.count_nonzero(scene(points)[:, 1] > TOP + 0.1) == np.count_nonzero(above) > 1000


def test_no_end_effector_on_the_table_a_person_stands_behind() -> None:
    """A person swaying behind a table joins it in one component, which their motion keeps
    foreground (the static background's rule), and the table's corners and legs become
    end-effectors. Without its top, the table's legs are parts of their own that never move,
    and the background drops them."""
    frames = [shot(scenes.person('t_pose', x=0.02 * (k % 4), z=-2.7), table()).frame
              for k in range(12)]

    def on_table(params: EndeffParams) -> int:
        background = BackgroundModel()
        found = 0
        for k, frame in enumerate(frames):
            frame = dataclasses.replace(frame, stamp_ns=k * 33_333_333)
            est = estimate_frame(frame, params, background=background)
            if k >= 9:  # learning is over (0.2 s) and the table's legs were seen still
                found += int(np.count_nonzero(in_table(est.positions())))
        return found

    assert on_table(EndeffParams(table_min_area=0.0)) >= 3  # what the rule removes
    assert on_table(EndeffParams()) == 0


@pytest.mark.parametrize('pose', ['t_pose', 'arms_down'])
def test_a_person_alone_loses_no_point(pose: str) -> None:
    """A level slab through a standing person (arms out or down) holds a ring of every part at
    that height; projected onto the level it is a thin curve, with no inside."""
    frame = shot(scenes.person(pose, z=-2.6)).frame
    assert len(cloud(frame)) == len(cloud(frame, table_min_area=0.0)) > 1000


def test_a_chair_keeps_its_seat() -> None:
    """A chair's seat (45 x 44 cm) is level but small: the chair stays one entity, whose legs
    are end-effectors."""
    frame = shot(scenes.placed_chair(0.3, z=-2.2)).frame
    assert len(cloud(frame)) == len(cloud(frame, table_min_area=0.0)) > 500


def test_a_low_level_surface_is_left_alone() -> None:
    """A surface lower than 0.2 m (a person lying on the floor shows a level back) is not a
    table, however large."""
    frame = shot(table(height=0.15, width=1.0, depth=0.8)).frame  # less than a wall
    assert on_top(cloud(frame), 0.15) == on_top(cloud(frame, table_min_area=0.0), 0.15) > 500


def test_the_threshold_is_the_area_inside_the_rim() -> None:
    """A 0.8 x 0.6 m top covers 0.48 m^2, 0.6 x 0.4 m of cells once its 10 cm rim is eroded
    (about 0.2-0.3 m^2): dropped with a threshold of 0.15 m^2, kept with 0.5 m^2."""
    frame = shot(table(width=0.8, depth=0.6)).frame
    assert on_top(cloud(frame, table_min_area=0.15)) == 0
    assert on_top(cloud(frame, table_min_area=0.5)) == on_top(cloud(frame, table_min_area=0.0))


def test_a_body_the_table_hides_ends_there_as_a_cut() -> None:
    """Without its top, a table hides the body behind it: the body seen over the top ends at
    the top's far edge, and the table's legs end under it. Those ends are cuts (the points
    beside the dropped top, not nearer than it), dropped like the image border's; the head
    and hands are not beside it."""
    s = shot(scenes.person('t_pose', z=-2.6), table())
    cloud_ = foreground_cloud(s.frame.depth, s.frame.intrinsics, PARAMS)
    assert cloud_.cut is not None
    heights = scene(cloud_.points)[:, 1]
    assert np.count_nonzero(cloud_.cut & (np.abs(heights - 0.8) < 0.1)) > 10  # over the top
    assert not np.any(cloud_.cut & (heights > 1.1))  # chest, arms, head
    ends = []
    # The cut's own verdict, the thresholds alone (the candidate scorer weighs it as evidence).
    rules = PARAMS.replace(candidate_floor=0.0)
    for params in (rules, rules.replace(drop_cut_ends=False)):
        pos = estimate_frame(s.frame, params).positions()
        false = np.linalg.norm(pos[:, None] - s.gt[None], axis=2).min(axis=1) > 0.15
        ends.append(int(np.count_nonzero(false & (scene(pos)[:, 1] > 0.15))))  # off the floor
    assert ends[0] == 0
    assert ends[1] >= 2  # the body's cut and the table legs' tops
    assert cloud(s.frame, table_min_area=0.0).shape[0] > len(cloud_.points)  # the top went


def test_a_body_in_front_of_the_table_is_not_cut() -> None:
    """A person between the camera and a table hides part of its top; nothing of them lies
    beyond the top, so nothing of them is cut (the table's legs are)."""
    s = shot(scenes.person('t_pose', z=-1.5), table(z=-2.6, width=1.8, depth=0.9))
    cloud_ = foreground_cloud(s.frame.depth, s.frame.intrinsics, PARAMS)
    person = scene(cloud_.points)[:, 2] > -1.8
    assert np.count_nonzero(person) > 500
    assert cloud_.cut is not None and np.count_nonzero(cloud_.cut & ~person) > 5  # table legs
    assert not np.any(cloud_.cut & person)


def test_a_robot_arm_standing_on_a_table_keeps_its_gripper() -> None:
    """A robot arm whose pedestal stands on a table: the top goes, the arm stays an entity of
    its own, and its gripper is found; its pedestal's foot, beside the dropped top, is cut
    (with the table kept it was no end either: the table's corners were)."""
    arm = scenes.placed_robot_arm(x=0.0, z=-2.3)
    lift = np.array([0.0, TOP, 0.0])
    on_table = Entity([p.transformed(np.eye(3), lift) for p in arm.prims], arm.gt + lift,
                      arm.gt_ids, arm.gt_prims, arm.gt_radius)
    s = shot(on_table, table(z=-2.3))
    pos = estimate_frame(s.frame, PARAMS).positions()
    gripper = s.gt[1]
    assert np.linalg.norm(pos - gripper, axis=1).min() < 0.15
    assert not np.any(in_table(pos) & (scene(pos)[:, 1] > 0.15))  # nothing on the table
