"""Synthetic benchmark data: bags read back with rosbags, ground truth, determinism.

The quick bags are generated once per session into a temporary directory (never committed).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from endeff_ros.synth import GROUPS, SEQUENCES, render_person_frame, render_sequence, scenes
from endeff_ros.synth import cli as synth_cli
from endeff_ros.synth import sheet as synth_sheet
from endeff_ros.synth.frames import COLOR_JITTER_NS, PERIOD_NS, T0_NS, dropped_frames
from endeff_ros.synth.render import FLOOR, WALL, background, default_camera, normals, render
from endeff_ros.synth.sequences import (
    PERSON_SEQUENCES,
    QUICK_FRAMES,
    SPECS,
    contact_distances,
    frame_time,
    scene,
)
from endeff_ros.synth.shapes import _inside, box, capsule, ellipsoid, rot_y, surface_distance

TOPICS = {
    '/camera/color/image_raw': 'sensor_msgs/msg/Image',
    '/camera/depth/image_raw': 'sensor_msgs/msg/Image',
    '/camera/depth/camera_info': 'sensor_msgs/msg/CameraInfo',
    '/ground_truth/end_effectors': 'sensor_msgs/msg/PointCloud2',
}
FRAME_ID = 'camera_color_optical_frame'
STORAGES = ('mcap', 'sqlite3')
TS = get_typestore(Stores.ROS2_JAZZY)


def _stamp(msg) -> int:
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def read_bag(path: Path) -> dict[str, list]:
    """topic -> list of (log time, deserialised message)."""
    out: dict[str, list] = {}
    with AnyReader([path], default_typestore=TS) as reader:
        for conn, t, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t, reader.deserialize(raw, conn.msgtype)))
        types = {c.topic: c.msgtype for c in reader.connections}
    out['__types__'] = types
    return out


def depth_of(msg) -> np.ndarray:
    buf = np.asarray(msg.data, dtype=np.uint8)
    if msg.encoding == '16UC1':
        mm = buf.view('<u2').reshape(msg.height, msg.width).astype(np.float32)
        return np.where(mm > 0, mm / np.float32(1000.0), np.float32(np.nan))
    return buf.view('<f4').reshape(msg.height, msg.width)


def cloud_of(msg) -> tuple[np.ndarray, np.ndarray]:
    rec = np.asarray(msg.data, dtype=np.uint8).view(
        np.dtype([('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('id', '<u4')]))
    return np.stack([rec['x'], rec['y'], rec['z']], 1), rec['id']


@pytest.fixture(scope='session')
def bag_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp('synth')
    counts = synth_cli.generate(out, list(SEQUENCES), list(STORAGES), quick=True, seed=0,
                                jobs=2)
    assert counts == {n: QUICK_FRAMES for n in SEQUENCES}
    return out


@pytest.fixture(scope='session')
def bags(bag_dir) -> dict[tuple[str, str], dict]:
    return {(s, n): read_bag(bag_dir / s / n) for s in STORAGES for n in SEQUENCES}


@pytest.fixture(scope='session')
def api_frames() -> dict[str, list]:
    return {n: list(render_sequence(n, quick=True, seed=0)) for n in SEQUENCES}


def test_names_and_groups():
    assert SEQUENCES == ('jumping_in_place', 'jumping_jacks', 'waving_two_hands',
                         'waving_one_hand', 'bending', 'punching', 'clapping', 'star', 'chair',
                         'robot_arm', 'two_people')
    assert GROUPS['no_occlusion'] == list(SEQUENCES[:4])
    assert GROUPS['occlusion'] == ['bending', 'punching', 'clapping']
    assert GROUPS['generic'] == ['star', 'chair', 'robot_arm', 'two_people']
    assert synth_cli.select('occlusion,star') == ['bending', 'punching', 'clapping', 'star']
    with pytest.raises(ValueError, match='unknown sequence'):
        synth_cli.select('dancing')
    encs = {s.depth_encoding for s in SPECS.values()} | {s.color_encoding for s in SPECS.values()}
    assert encs == {'16UC1', '32FC1', 'rgb8', 'bgr8'}
    assert {s.info_every for s in SPECS.values()} == {1, 10}


@pytest.mark.parametrize('storage', STORAGES)
def test_topics_types_encodings(bags, storage):
    for name in SEQUENCES:
        bag, spec = bags[(storage, name)], SPECS[name]
        assert bag['__types__'] == TOPICS, name
        drop_c, drop_d = dropped_frames(name, QUICK_FRAMES, 0)
        assert len(bag['/camera/depth/image_raw']) == QUICK_FRAMES - len(drop_d)
        assert len(bag['/camera/color/image_raw']) == QUICK_FRAMES - len(drop_c)
        assert len(bag['/ground_truth/end_effectors']) == QUICK_FRAMES - len(drop_d)
        n_info = sum(1 for i in range(QUICK_FRAMES)
                     if i % spec.info_every == 0 and i not in drop_d)
        assert len(bag['/camera/depth/camera_info']) == n_info
        for topic in TOPICS:
            for _, msg in bag[topic]:
                assert msg.header.frame_id == FRAME_ID
        for _, msg in bag['/camera/depth/image_raw']:
            assert (msg.width, msg.height, msg.encoding) == (640, 480, spec.depth_encoding)
            assert msg.step == 640 * (2 if spec.depth_encoding == '16UC1' else 4)
        for _, msg in bag['/camera/color/image_raw']:
            assert (msg.width, msg.height, msg.encoding) == (640, 480, spec.color_encoding)
            assert msg.step == 640 * 3
        for _, msg in bag['/camera/depth/camera_info']:
            assert np.allclose(msg.k, [525, 0, 319.5, 0, 525, 239.5, 0, 0, 1])
            assert (msg.width, msg.height) == (640, 480)
        for _, msg in bag['/ground_truth/end_effectors']:
            assert msg.height == 1 and msg.point_step == 16
            assert [(f.name, f.offset, f.datatype) for f in msg.fields] == [
                ('x', 0, 7), ('y', 4, 7), ('z', 8, 7), ('id', 12, 6)]
            n_gt = {'star': 5, 'chair': 6, 'robot_arm': 2, 'two_people': 10}.get(name, 5)
            _, ids = cloud_of(msg)
            assert sorted(ids.tolist()) == list(range(n_gt))


@pytest.mark.parametrize('storage', STORAGES)
def test_stamps(bags, storage):
    for name in SEQUENCES:
        bag = bags[(storage, name)]
        depth = [_stamp(m) for _, m in bag['/camera/depth/image_raw']]
        gt = [_stamp(m) for _, m in bag['/ground_truth/end_effectors']]
        color = [_stamp(m) for _, m in bag['/camera/color/image_raw']]
        assert gt == depth
        assert all((s - T0_NS) % PERIOD_NS == 0 for s in depth)
        assert depth == sorted(depth)
        grid = T0_NS + PERIOD_NS * np.round((np.array(color) - T0_NS) / PERIOD_NS)
        jitter = np.array(color) - grid
        assert np.abs(jitter).max() <= COLOR_JITTER_NS
        assert np.abs(jitter).max() > 0
        for topic in TOPICS:
            for log, msg in bag[topic]:
                assert 0 < log - _stamp(msg) < 10_000_000  # receive time after the stamp


def test_bag_matches_api_and_storages_agree(bags, api_frames):
    for name in SEQUENCES:
        frames = {f.stamp_ns: f for f in api_frames[name]}
        cframes = {f.color_stamp_ns: f for f in api_frames[name]}
        for storage in STORAGES:
            bag = bags[(storage, name)]
            for _, msg in bag['/camera/depth/image_raw']:
                f = frames[_stamp(msg)]
                np.testing.assert_allclose(depth_of(msg), f.depth, atol=1e-6)
            for _, msg in bag['/ground_truth/end_effectors']:
                f = frames[_stamp(msg)]
                pts, ids = cloud_of(msg)
                np.testing.assert_allclose(pts, f.gt, atol=1e-5)
                assert (ids == f.gt_ids).all()
            for _, msg in bag['/camera/color/image_raw']:
                f = cframes[_stamp(msg)]
                img = np.asarray(msg.data, np.uint8).reshape(480, 640, 3)
                if msg.encoding == 'bgr8':
                    img = img[..., ::-1]
                assert (img == f.color).all()


def test_dropped_frames(api_frames):
    for name in SEQUENCES:
        frames = api_frames[name]
        assert all(f.color is not None and f.depth is not None for f in frames[:3])
        assert sum(f.color is None for f in frames) >= 1
        assert sum(f.depth is None for f in frames) >= 1
        for f in frames:
            assert f.frame_id == FRAME_ID
            assert f.gt.shape == (len(f.gt_ids), 3) and f.gt_visible.shape == f.gt_ids.shape
            if f.depth is not None:
                assert f.depth.dtype == np.float32 and f.depth.shape == (480, 640)
            if f.color is not None:
                assert f.color.dtype == np.uint8 and f.color.shape == (480, 640, 3)


def test_determinism_from_seed(bag_dir, tmp_path, api_frames):
    again = list(render_sequence('clapping', quick=True, seed=0))
    for a, b in zip(again, api_frames['clapping']):
        assert a.stamp_ns == b.stamp_ns and a.color_stamp_ns == b.color_stamp_ns
        for x, y in ((a.depth, b.depth), (a.color, b.color)):
            assert (x is None) == (y is None)
            if x is not None:
                np.testing.assert_array_equal(x, y)
        np.testing.assert_array_equal(a.gt, b.gt)
    synth_cli.generate(tmp_path, ['clapping'], ['mcap'], quick=True, seed=0, jobs=1)
    one, two = read_bag(tmp_path / 'mcap' / 'clapping'), read_bag(bag_dir / 'mcap' / 'clapping')
    for topic in TOPICS:
        assert [t for t, _ in one[topic]] == [t for t, _ in two[topic]]
        for (_, m1), (_, m2) in zip(one[topic], two[topic]):
            assert TS.serialize_cdr(m1, m1.__msgtype__) == TS.serialize_cdr(m2, m2.__msgtype__)
    other = next(iter(render_sequence('clapping', quick=True, seed=1)))
    assert not np.array_equal(np.nan_to_num(other.depth), np.nan_to_num(again[0].depth))


def test_ground_truth_projects_onto_foreground_depth(api_frames):
    """Visible end-effectors land on valid depth a little in front of the part's centre."""
    for name in SEQUENCES:
        n_vis = 0
        for f in api_frames[name]:
            if f.depth is None:
                continue
            uv = f.intrinsics.project(f.gt)
            for (u, v), p, vis in zip(uv, f.gt, f.gt_visible):
                assert 0.4 < p[2] < 4.3 and abs(p[0]) < 1.6 and abs(p[1]) < 2.0, name
                if not vis:
                    continue
                n_vis += 1
                ui, vi = int(round(u)), int(round(v))
                win = f.depth[max(0, vi - 2):vi + 3, max(0, ui - 2):ui + 3]
                ok = np.isfinite(win) & (win > p[2] - 0.25) & (win < p[2] + 0.10)
                assert ok.any(), (name, f.index, p)
        assert n_vis > 0.6 * QUICK_FRAMES * len(api_frames[name][0].gt_ids), name


def test_scene_geometry_inside_foreground_box():
    cam = default_camera()
    bg = background(cam)
    assert bg.z[bg.owner == WALL].min() > 4.6
    assert (bg.owner != WALL).sum() > 0 and (bg.owner == FLOOR).sum() > 0
    for name in SEQUENCES:
        for i in range(0, SPECS[name].frames, 12):
            r = render(scene(name, frame_time(name, i)), cam)
            v, u = np.nonzero(r.owner >= 0)
            z = r.z[v, u]
            x, y = (u - 319.5) / 525 * z, (v - 239.5) / 525 * z
            assert np.abs(x).max() < 1.6 and np.abs(y).max() < 2.0, name
            assert z.min() > 0.4 and z.max() < 4.3, name


def test_occlusion_sequences_have_contacts():
    """Hands within 5 cm of the torso or of each other (body model, not the image)."""
    for name in GROUPS['occlusion']:
        close = 0
        for i in range(0, SPECS[name].frames, 2):
            d = contact_distances(scene(name, frame_time(name, i)))
            close += min(d.values()) < 0.05
        assert close >= 4, name


def test_no_occlusion_sequences_keep_hands_clear():
    for name in GROUPS['no_occlusion']:
        clear = 0
        frames = range(0, SPECS[name].frames, 4)
        for i in frames:
            e = scene(name, frame_time(name, i))
            d = contact_distances(e)
            p, parts = e.prims, e.parts
            legs = min(surface_distance(p[parts[f'{s}_hand']], p[parts[f'{side}_{k}']])
                       for s in 'lr' for side in 'lr' for k in ('thigh', 'shin'))
            clear += min(min(d.values()), legs) > 0.10
        assert clear >= 0.9 * len(frames), name


def test_person_sequences_two_repetitions_and_self_occlusion():
    cam = default_camera()
    for name in PERSON_SEQUENCES:
        assert 70 <= SPECS[name].frames <= 90
    # Self-occlusion in the occlusion group: pixels of the torso or legs hidden by a hand,
    # forearm or the head (or the legs hidden by the torso), from the body model.
    for name in GROUPS['occlusion']:
        frames_with = 0
        for i in range(0, SPECS[name].frames, 8):
            e = scene(name, frame_time(name, i))
            frames_with += _self_occluded_pixels(e, cam) > 150
        assert frames_with >= 3, name


def _self_occluded_pixels(e, cam) -> int:
    from endeff_ros.synth.render import _bbox, intersect, rays

    r = render(e, cam)
    parts = e.parts
    arms_head = {parts[k] for k in ('head', 'l_hand', 'r_hand', 'l_fore', 'r_fore')}
    torso = {parts[k] for k in ('chest', 'abdomen', 'pelvis')}
    legs = {parts[f'{s}_{k}'] for s in 'lr' for k in ('thigh', 'shin')}
    hidden = 0
    d_all = rays(cam.intrinsics)
    for i in torso | legs:
        p = r.prims[i]
        v0, v1, u0, u1 = _bbox(p, cam.intrinsics)
        t = intersect(p, d_all[v0:v1, u0:u1].reshape(-1, 3)).reshape(v1 - v0, u1 - u0)
        occluders = arms_head | (torso if i in legs else set())
        hidden += int((np.isfinite(t) & np.isin(r.owner[v0:v1, u0:u1], list(occluders))).sum())
    return hidden


def test_person_frame():
    cam = default_camera()
    for pose in ('t_pose', 'arms_down'):
        f = render_person_frame(pose, seed=0)
        assert f.depth.shape == (480, 640) and f.color.shape == (480, 640, 3)
        assert f.gt_visible.all() and list(f.gt_ids) == [0, 1, 2, 3, 4]
        v, u = np.nonzero(np.isfinite(f.depth))
        z = f.depth[v, u].astype(np.float64)
        pts = np.stack([(u - 319.5) / 525 * z, (v - 239.5) / 525 * z, z], 1)
        above_floor = (pts @ cam.rotation + cam.position)[:, 1] > 0.05
        n_fg = int((above_floor & (z < 4.3)).sum())
        assert 20_000 <= n_fg <= 30_000, n_fg
        assert 2.3 < f.gt[:, 2].mean() < 3.0
    with pytest.raises(ValueError):
        render_person_frame('handstand')


def test_scene_shot_is_the_ideal_render_with_its_ground_truth():
    """``scenes.shoot``: the depth is the ray caster's (NaN where nothing is hit), the ground
    truth its optical-frame centres; without floor only the entity has depth; the person in
    ``POSES`` is the one ``render_person_frame`` draws (same hands and feet)."""
    person = scenes.person('t_pose', z=-2.5)
    shot = scenes.shoot(person, default_camera())
    ren = render(person, default_camera())
    np.testing.assert_array_equal(np.isfinite(shot.frame.depth), np.isfinite(ren.z))
    np.testing.assert_allclose(shot.frame.depth[np.isfinite(ren.z)], ren.z[np.isfinite(ren.z)],
                               rtol=1e-6)
    np.testing.assert_allclose(shot.gt, ren.gt)
    np.testing.assert_allclose(shot.gt, render_person_frame('t_pose').gt, atol=1e-9)
    assert shot.gt_visible.all()
    for k in range(5):  # each end-effector is the centre of its part
        np.testing.assert_allclose(shot.part(k).center, shot.gt[k], atol=1e-9)
    floating = scenes.shoot(person, default_camera(), floor=False)
    entity = floating.frame.depth[np.isfinite(floating.frame.depth)]
    assert 15_000 < entity.size < np.isfinite(shot.frame.depth).sum() / 4
    assert entity.max() < 3.0  # no floor, no wall
    with pytest.raises(ValueError, match='pose must be one of'):
        scenes.person('handstand')


@pytest.mark.parametrize('n, keep', [(3, None), (6, None), (5, (1, 2, 4))])
def test_scene_star_limbs(n, keep):
    """``scenes.star``: one end cap per kept limb, ``length`` m from the hub, ids = limb
    indices, in the image plane, each end cap seen from a level camera."""
    star = scenes.star(n, keep=keep, length=0.5)
    ids = list(range(n)) if keep is None else list(keep)
    assert list(star.gt_ids) == ids
    hub = star.prims[0].center
    np.testing.assert_allclose(np.linalg.norm(star.gt - hub, axis=1), 0.5)
    np.testing.assert_allclose(star.gt[:, 2], hub[2])
    angles = np.arctan2(star.gt[:, 1] - hub[1], star.gt[:, 0] - hub[0])
    np.testing.assert_allclose(np.cos(angles - 0.3 - 2 * np.pi * np.array(ids) / n), 1.0)
    assert scenes.shoot(star, floor=False).gt_visible.all()


@pytest.mark.parametrize('part', [
    capsule([0.1, 0.2, -2.0], [0.4, 0.5, -2.2], 0.05, [0, 0, 1], (1, 1, 1), 0, 'limb'),
    box([0.0, 0.5, -2.0], rot_y(0.4), [0.2, 0.05, 0.1], (1, 1, 1), 0, 'seat'),
    ellipsoid([0.0, 1.0, -2.5], rot_y(0.3), [0.08, 0.08, 0.08], (1, 1, 1), 0, 'cap'),
])
def test_distance_to_part(part):
    """0 inside the solid, positive outside, and exactly the step for points stepped out of
    the surface along its outward normal."""
    rng = np.random.default_rng(3)
    points = part.center + rng.uniform(-0.5, 0.5, (400, 3))
    d = scenes.distance_to_part(part, points)
    assert np.all(d[_inside(part, points)] == 0) and np.all(d[~_inside(part, points)] > 0)
    surface = part.surface_points(200)
    d = scenes.distance_to_part(part, surface + 0.07 * normals(part, surface))
    np.testing.assert_allclose(d, 0.07, atol=1e-9)
    assert np.all(scenes.distance_to_part(part, surface - 0.01 * normals(part, surface)) == 0)


def test_contact_sheet(bag_dir, tmp_path):
    out = tmp_path / 'sheet.png'
    args = argparse.Namespace(bags=[bag_dir / 'mcap' / 'clapping', bag_dir / 'sqlite3' / 'star'],
                              out=out, frames=3, scale=0.25)
    assert synth_sheet.run(args) == 0
    img = cv2.imread(str(out))
    assert img is not None and img.shape[0] > 100 and img.shape[1] > 300
    assert img.std() > 10
    assert synth_sheet.find_bags([bag_dir]) and len(synth_sheet.find_bags([bag_dir])) == 11


def test_a_bag_appears_only_once_complete(bag_dir: Path, tmp_path: Path) -> None:
    """An interrupted write leaves neither a short bag under the bag's name nor a hidden
    partial one, and the bag of an earlier run stays; a partial directory left by a killed
    process is not taken for a bag and is swept by the next write."""
    from endeff_ros.bag.outputs import partial_dir
    from endeff_ros.bag.reader import find_bags
    from endeff_ros.synth.writer import write_bags

    name = 'star'
    path = tmp_path / 'mcap' / name
    first = synth_cli.generate_one(name, tmp_path, ['mcap'], True, 0)
    before = sorted((p.name, p.stat().st_size) for p in path.iterdir())

    def interrupted():
        for i, frame in enumerate(render_sequence(name, quick=True, seed=0)):
            if i == 4:
                raise KeyboardInterrupt
            yield frame

    with pytest.raises(KeyboardInterrupt):
        write_bags(interrupted(), SPECS[name], {'mcap': path})
    assert sorted((p.name, p.stat().st_size) for p in path.iterdir()) == before
    assert [p.name for p in path.parent.iterdir()] == [name]

    stale = partial_dir(path, pid=2**22 + 1)  # beyond any pid in use
    (stale / 'x').mkdir(parents=True)
    (stale / 'x' / 'short_0.mcap').write_bytes(b'')
    assert find_bags([tmp_path]) == [path]
    assert synth_cli.generate_one(name, tmp_path, ['mcap'], True, 0) == first
    assert [p.name for p in path.parent.iterdir()] == [name]
    assert (path / f'{name}.mcap').read_bytes() == (
        bag_dir / 'mcap' / name / f'{name}.mcap').read_bytes()
