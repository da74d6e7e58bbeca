"""Mocap readers: BVH and DeepMimic forward kinematics, retargeting, normalisation, fetching.

Every motion here is written by the test itself, so the expected positions follow from the
offsets and angles by hand (no network, no third-party files).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from endeff_ros.synth.mocap import catalogue, deepmimic, fetch
from endeff_ros.synth.mocap.bvh import parse_bvh
from endeff_ros.synth.mocap.clip import JOINT_INDEX as J
from endeff_ros.synth.mocap.kin import MocapError, axis_rotation
from endeff_ros.synth.mocap.retarget import loop_cycles, resample, unit_scale
from endeff_ros.synth.mocap.sources import BANDAI_MAP, load_bvh_positions

# -- BVH basics ---------------------------------------------------------------------------------

LEG = """HIERARCHY
ROOT hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT knee
  {
    OFFSET 0 -40 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 -40 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.5
1 2 3 0 0 0 0 0 0
1 2 3 90 0 0 0 0 90
"""


def test_bvh_root_rotation_moves_child_and_end_site():
    bvh = parse_bvh(LEG)
    assert bvh.names == ('hips', 'knee', 'knee_End')
    assert bvh.fps == pytest.approx(2.0)
    fk = bvh.forward()
    np.testing.assert_allclose(fk['knee'][1][0], [1, -38, 3], atol=1e-9)
    np.testing.assert_allclose(fk['knee_End'][1][0], [1, -78, 3], atol=1e-9)
    # hips turned 90 deg about z: the thigh (0, -40, 0) now points to +x
    np.testing.assert_allclose(fk['knee'][1][1], [41, 2, 3], atol=1e-9)
    # the knee's own 90 deg about y leaves the shin (0, -40, 0) on the y axis: along +x too
    np.testing.assert_allclose(fk['knee_End'][1][1], [81, 2, 3], atol=1e-9)


def _two_joint(order: str) -> str:
    chans = ' '.join(f'{a}rotation' for a in order)
    return f"""HIERARCHY
ROOT a
{{
  OFFSET 0 0 0
  CHANNELS {len(order)} {chans}
  JOINT b
  {{
    OFFSET 1 0 0
    CHANNELS 0
  }}
}}
MOTION
Frames: 1
Frame Time: 0.1
{' '.join(['90'] * len(order))}
"""


@pytest.mark.parametrize(('order', 'expected'), [('XY', [0, 1, 0]), ('YX', [0, 0, -1]),
                                                 ('ZY', [0, 0, -1]), ('YZ', [0, 1, 0])])
def test_bvh_channel_order_composes_left_to_right(order, expected):
    # XY: R = Rx(90) Ry(90); Ry(90) (1,0,0) = (0,0,-1), then Rx(90) -> (0,1,0).
    # YX: Rx(90) keeps (1,0,0), then Ry(90) -> (0,0,-1). Likewise for Z and Y.
    pos = parse_bvh(_two_joint(order)).forward()['b'][1][0]
    np.testing.assert_allclose(pos, expected, atol=1e-9)


def test_bvh_position_channel_replaces_offset():
    text = LEG.replace('CHANNELS 3 Zrotation Xrotation Yrotation',
                       'CHANNELS 4 Yposition Zrotation Xrotation Yrotation')
    text = text.replace('1 2 3 0 0 0 0 0 0\n', '1 2 3 0 0 0 -30 0 0 0\n')
    text = text.replace('1 2 3 90 0 0 0 0 90\n', '1 2 3 0 0 0 -20 0 0 0\n')
    fk = parse_bvh(text).forward(['knee'])
    assert set(fk) == {'hips', 'knee'}
    np.testing.assert_allclose(fk['knee'][1][:, 1], [2 - 30, 2 - 20])


@pytest.mark.parametrize(('text', 'words'), [
    ('HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Wrotation\n}\nMOTION\nFrames: 1\n'
     'Frame Time: 0.1\n0\n', 'bad channels'),
    ('HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n}\nMOTION\nFrames: 2\n'
     'Frame Time: 0.1\n0\n', 'expected 2 frames'),
    ('HIERARCHY\nROOT a\n{\nOFFSET 0 0\n}\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n',
     'expected numbers'),
    ('ROOT a', 'not a BVH file'),
])
def test_bvh_bad_input_names_the_problem(text, words):
    with pytest.raises(MocapError, match=words):
        parse_bvh(text, name='t.bvh')


# -- a synthetic humanoid with Bandai joint names ----------------------------------------------

PELVIS_Y = 0.95
#: joint, parent, offset (m, y up, facing +z, the person's left is +x)
HUMANOID = [
    ('Hips', None, (0.0, PELVIS_Y, 0.0)),
    ('Spine', 'Hips', (0.0, 0.12, 0.0)),
    ('Chest', 'Spine', (0.0, 0.15, 0.0)),
    ('Neck', 'Chest', (0.0, 0.20, 0.0)),
    ('Head', 'Neck', (0.0, 0.10, 0.0)),
]
for _s, _x in (('L', 1.0), ('R', -1.0)):
    HUMANOID += [
        (f'UpperArm_{_s}', 'Chest', (_x * 0.18, 0.15, 0.0)),
        (f'LowerArm_{_s}', f'UpperArm_{_s}', (_x * 0.28, 0.0, 0.0)),
        (f'Hand_{_s}', f'LowerArm_{_s}', (_x * 0.25, 0.0, 0.0)),
        (f'UpperLeg_{_s}', 'Hips', (_x * 0.10, -0.05, 0.0)),
        (f'LowerLeg_{_s}', f'UpperLeg_{_s}', (0.0, -0.42, 0.0)),
        (f'Foot_{_s}', f'LowerLeg_{_s}', (0.0, -0.42, 0.0)),
        (f'Toes_{_s}', f'Foot_{_s}', (0.0, -0.05, 0.12)),
    ]
#: Toe tip (5 cm beyond Toes along the ankle-to-toe bone) is the lowest foot joint.
TOE_DROP = 0.05 * 0.05 / np.hypot(0.05, 0.12)
ANKLE_Y = PELVIS_Y - 0.05 - 0.84


def humanoid_bvh(rows: np.ndarray, *, unit: float = 1.0, z_up: bool = False,
                 frame_time: float = 1 / 30) -> str:
    """BVH text of ``HUMANOID`` (lengths divided by ``unit`` metres) with motion ``rows``
    (T, 6 + 3 * (J - 1)): root position (m) and ZXY angles, then ZXY angles per joint."""
    kids: dict[str | None, list[int]] = {}
    for k, (_, parent, _) in enumerate(HUMANOID):
        kids.setdefault(parent, []).append(k)

    def vec(v):
        x, y, z = (c / unit for c in v)
        return (x, -z, y) if z_up else (x, y, z)

    def block(k: int, depth: int) -> list[str]:
        name, parent, off = HUMANOID[k]
        pad = '  ' * depth
        kind = 'ROOT' if parent is None else 'JOINT'
        chans = ('6 Xposition Yposition Zposition' if parent is None else '3') + \
            ' Zrotation Xrotation Yrotation'
        lines = [f'{pad}{kind} {name}', pad + '{', f'{pad}  OFFSET {" ".join(map(str, vec(off)))}',
                 f'{pad}  CHANNELS {chans}']
        for c in kids.get(name, []):
            lines += block(c, depth + 1)
        if name not in kids:
            lines += [f'{pad}  End Site', pad + '  {', f'{pad}    OFFSET 0 0 0', pad + '  }']
        return lines + [pad + '}']

    motion = np.array(rows, dtype=np.float64).copy()
    motion[:, :3] = [vec(r) for r in motion[:, :3]]
    if z_up:
        # the up axis moved from y to z, so the root's yaw (Y channel) is now about -z... keep
        # the test simple: z-up files here carry no root rotation.
        assert not np.any(motion[:, 3:6])
    body = '\n'.join(' '.join(f'{v:.9g}' for v in r) for r in motion)
    return ('HIERARCHY\n' + '\n'.join(block(0, 0)) + f'\nMOTION\nFrames: {len(motion)}\n'
            f'Frame Time: {frame_time}\n{body}\n')


def rest_rows(n: int = 2, root=(0.0, PELVIS_Y, 0.0)) -> np.ndarray:
    rows = np.zeros((n, 6 + 3 * (len(HUMANOID) - 1)))
    rows[:, :3] = root
    return rows


def _load(tmp_path: Path, text: str, **kw) -> np.ndarray:
    path = tmp_path / 'h.bvh'
    path.write_text(text)
    return load_bvh_positions(path, BANDAI_MAP, **kw)


def test_rest_pose_retargets_to_known_positions(tmp_path):
    pos = _load(tmp_path, humanoid_bvh(rest_rows()))
    floor = ANKLE_Y - 0.05 - TOE_DROP   # source height of the lowest foot joint
    expect = {
        'pelvis': (0.0, PELVIS_Y - floor, 0.0),
        'head': (0.0, PELVIS_Y + 0.57 - floor, 0.0),
        'head_top': (0.0, PELVIS_Y + 0.77 - floor, 0.0),      # 20 cm beyond Head
        'l_wrist': (0.71, PELVIS_Y + 0.42 - floor, 0.0),
        'r_hand_end': (-0.89, PELVIS_Y + 0.42 - floor, 0.0),  # 18 cm beyond the hand
        'l_ankle': (0.10, ANKLE_Y - floor, 0.0),
        'l_toe': (0.10, 0.0, 0.12 + 0.05 * 0.12 / np.hypot(0.05, 0.12)),
    }
    for joint, xyz in expect.items():
        np.testing.assert_allclose(pos[0, J[joint]], xyz, atol=1e-6, err_msg=joint)


@pytest.mark.parametrize(('unit', 'z_up'), [(0.01, False), (0.0254, False), (1.0, True),
                                            (0.01, True)])
def test_units_and_up_axis_are_detected(tmp_path, unit, z_up):
    ref = _load(tmp_path, humanoid_bvh(rest_rows()))
    rows = rest_rows()
    pos = _load(tmp_path, humanoid_bvh(rows, unit=unit, z_up=z_up))
    np.testing.assert_allclose(pos, ref, atol=1e-6)


def test_unit_scale_thresholds():
    assert unit_scale(1.5) == 1.0
    assert unit_scale(60.0) == 0.0254
    assert unit_scale(150.0) == 0.01
    with pytest.raises(MocapError):
        unit_scale(0.0)


def test_facing_origin_and_floor_are_normalised(tmp_path):
    ref = _load(tmp_path, humanoid_bvh(rest_rows()))
    rows = rest_rows(root=(2.0, PELVIS_Y + 0.3, -1.0))
    rows[:, 5] = 70.0   # faces 70 deg away from +z, stands 2 m aside and 30 cm up
    pos = _load(tmp_path, humanoid_bvh(rows))
    np.testing.assert_allclose(pos, ref, atol=1e-9)
    p0 = ref[0]
    assert p0[J['pelvis'], 0] == 0.0 and p0[J['pelvis'], 2] == 0.0
    left = p0[J['l_hip']] - p0[J['r_hip']]
    assert left[0] > 0.19 and abs(left[2]) < 1e-9
    feet = ref[:, [J['l_ankle'], J['l_toe'], J['r_ankle'], J['r_toe']], 1]
    assert feet.min() == pytest.approx(0.0, abs=1e-12)
    rows = rest_rows()
    rows[:, 4] = 10.0   # leans 10 deg about x, the person's left: the head goes to the front
    lean = _load(tmp_path, humanoid_bvh(rows))[0]
    assert lean[J['head'], 2] > 0.05 and abs(lean[J['head'], 0]) < 1e-9


def test_resampled_to_30_fps(tmp_path):
    n = 121   # 1 s at 120 fps, the root walking 1.2 m along the person's front
    rows = rest_rows(n)
    rows[:, 2] = np.linspace(0.0, 1.2, n)
    pos = _load(tmp_path, humanoid_bvh(rows, frame_time=1 / 120))
    assert len(pos) == 31
    np.testing.assert_allclose(pos[:, J['pelvis'], 2], np.linspace(0.0, 1.2, 31), atol=1e-9)


def test_resample_interpolates_linearly():
    pos = np.zeros((3, 2, 3))
    pos[:, 0, 0] = [0.0, 1.0, 3.0]
    out = resample(pos, np.array([0.0, 0.1, 0.2]), fps=10.0)
    np.testing.assert_allclose(out[:, 0, 0], [0.0, 1.0, 3.0])
    out = resample(pos, np.array([0.0, 0.1, 0.2]), fps=20.0)
    np.testing.assert_allclose(out[:, 0, 0], [0.0, 0.5, 1.0, 2.0, 3.0])
    with pytest.raises(MocapError):
        resample(pos, np.array([0.0, 0.1, 0.1]))


def test_trim_window_and_skip(tmp_path):
    rows = rest_rows(61)
    rows[:, 0] = np.linspace(0.0, 2.0, 61)   # sideways, 1 m/s at 30 fps
    pos = _load(tmp_path, humanoid_bvh(rows), window=(0.5, 1.5), skip=3)
    assert len(pos) == 31
    # frame 0 is the pelvis origin; the person then moves 1 m to its left (+x)
    np.testing.assert_allclose(pos[-1, J['pelvis'], 0], 1.0, atol=1e-9)


def test_loop_cycles_continue_a_turning_motion():
    # a rigid pose turning about the vertical axis through the origin: looping one cycle must
    # give exactly the same motion continued, at every later time
    rng = np.random.default_rng(5)
    base = rng.normal(0.0, 0.3, (len(J), 3)) + [0.5, 1.0, 0.0]
    base[J['l_hip']] = (0.6, 0.9, 0.0)
    base[J['r_hip']] = (0.4, 0.9, 0.0)
    omega, times = 0.8, np.linspace(0.0, 1.2, 13)

    def pose(t):
        return base @ axis_rotation('y', omega * t).T

    pos = np.stack([pose(t) for t in times])
    out, out_t = loop_cycles(pos, times, 4.0)
    assert out_t[-1] >= 4.0 and np.all(np.diff(out_t) > 0)
    np.testing.assert_allclose(out, np.stack([pose(t) for t in out_t]), atol=1e-9)
    same, same_t = loop_cycles(pos, times, 1.0)
    assert same is pos and same_t is times
    # a small mismatch of the last frame is faded in: the seam is then continuous
    bent = pos.copy()
    bent[-1, J['l_wrist']] += (0.05, 0.0, 0.0)
    out, out_t = loop_cycles(bent, times, 4.0)
    n = len(bent)
    assert len(out) == len(out_t) > n
    np.testing.assert_allclose(out[:n - 3], bent[:n - 3], atol=1e-12)   # before the fade

    def shape(p):   # joint-to-joint distances: equal for rigidly moved copies of a pose
        return np.linalg.norm(p[..., :, None, :] - p[..., None, :, :], axis=-1)

    np.testing.assert_allclose(shape(out[n - 1]), shape(bent[0]), atol=1e-9)  # seam closed
    np.testing.assert_allclose(shape(out[n:2 * n - 1]), shape(out[1:n]), atol=1e-9)
    # a motion that does not come back to its start is no cycle: left unchanged
    bent[-1, J['l_wrist']] += (0.5, 0.0, 0.0)
    assert loop_cycles(bent, times, 4.0)[0] is bent


# -- DeepMimic ----------------------------------------------------------------------------------


def _dm_rows(n: int = 2) -> np.ndarray:
    rows = np.zeros((n, deepmimic.N_COLUMNS))
    rows[:, 0] = 1 / 30
    rows[:, 2] = 0.9
    col = 4
    for _, _, kind in (('root', '', 'sphere'), *deepmimic.JOINTS[1:]):
        if kind == 'sphere':
            rows[:, col] = 1.0
            col += 4
        elif kind == 'revolute':
            col += 1
    return rows


def _dm_text(rows: np.ndarray) -> str:
    return json.dumps({'Loop': 'none', 'Frames': rows.tolist()})


def _dm_col(joint: str) -> int:
    col = 8
    for name, _, kind in deepmimic.JOINTS[1:]:
        if name == joint:
            return col
        col += {'sphere': 4, 'revolute': 1}.get(kind, 0)
    raise KeyError(joint)


def test_deepmimic_identity_pose_is_the_offset_table():
    times, _, pos, wrap = deepmimic.parse_deepmimic(_dm_text(_dm_rows()))
    assert not wrap
    np.testing.assert_allclose(times, [0.0, 1 / 30])
    parent = {n: p for n, p, _ in deepmimic.JOINTS}
    for k, name in enumerate(deepmimic.NAMES):
        want = np.array([0.0, 0.9, 0.0])
        j = name
        while j:
            want = want + deepmimic.OFFSETS[j]
            j = parent[j]
        np.testing.assert_allclose(pos[0, k], want, atol=1e-12, err_msg=name)
    # sanity of the table itself: legs 0.83 m, the left side at -z
    left_ankle = pos[0, deepmimic.NAMES.index('left_ankle')]
    assert left_ankle[1] == pytest.approx(0.9 - 0.421546 - 0.40987)
    assert left_ankle[2] < 0


def test_deepmimic_joint_rotations_move_children():
    rows = _dm_rows()
    rows[1, _dm_col('right_knee')] = np.pi / 2                 # revolute, about z
    c = _dm_col('left_shoulder')
    rows[1, c:c + 4] = (np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0)   # 90 deg about x
    pos = deepmimic.parse_deepmimic(_dm_text(rows)).pos
    idx = deepmimic.NAMES.index
    np.testing.assert_allclose(pos[1, idx('right_ankle')] - pos[1, idx('right_knee')],
                               [0.40987, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(pos[1, idx('left_elbow')] - pos[1, idx('left_shoulder')],
                               [0.0, 0.0, -0.274788], atol=1e-12)
    np.testing.assert_allclose(pos[1, idx('left_wrist')] - pos[1, idx('left_elbow')],
                               [0.0, 0.0, -0.258947], atol=1e-12)
    np.testing.assert_allclose(pos[0, idx('right_ankle')] - pos[0, idx('right_knee')],
                               [0.0, -0.40987, 0.0], atol=1e-12)


@pytest.mark.parametrize(('text', 'words'), [
    ('{"Frames": [[1, 2, 3]]}', 'rows of 44'),
    ('not json', 'not a DeepMimic motion'),
])
def test_deepmimic_bad_input(text, words):
    with pytest.raises(MocapError, match=words):
        deepmimic.parse_deepmimic(text)


def test_deepmimic_compaction_keeps_the_motion():
    rng = np.random.default_rng(3)
    rows = _dm_rows(4) + rng.normal(0, 0.3, (4, deepmimic.N_COLUMNS)) * (np.arange(44) > 0)
    raw = _dm_text(rows).encode()
    back = np.array(json.loads(fetch.compact_deepmimic(raw))['Frames'])
    np.testing.assert_allclose(back, rows, atol=5e-7)
    assert len(fetch.compact_deepmimic(raw)) < len(raw)


# -- fetch into a cache, then the catalogue picks the clips up ---------------------------------


def _fake_bandai(root: Path, names: list[str]) -> None:
    text = humanoid_bvh(rest_rows(31), unit=0.01)
    for n in names:
        path = root / fetch.FETCH_SOURCES['bandai'].path(n)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    lic = root / 'dataset/Bandai-Namco-Research-Motiondataset-1/LICENSE'
    lic.write_text('licence text')


def _bandai_entries() -> list:
    return [e for e in catalogue.CLIPS if e.source == 'bandai']


def test_fetch_copies_only_the_selection_and_catalogue_loads_it(tmp_path):
    chosen = [e.file for e in _bandai_entries()[:2]]
    src = tmp_path / 'src'
    _fake_bandai(src, [*chosen, 'dataset-1_walk_unlisted_099.bvh'])
    res = fetch.fetch('bandai', src=str(src), dest=tmp_path / 'cache' / 'bandai')
    assert sorted(res.copied) == sorted(chosen)
    files = sorted(p.name for p in (tmp_path / 'cache' / 'bandai').iterdir())
    assert files == sorted([*chosen, 'LICENSE-dataset-1', 'NOTICE.md'])
    assert len(res.missing) == len(_bandai_entries()) - 2 + 1   # + dataset-2's licence
    clips = catalogue.load_clips(cache_dir=tmp_path / 'cache')
    fetched = [c for c in clips if c.source == 'bandai']
    assert sorted(c.name for c in fetched) == sorted(f'bandai/{Path(f).stem}' for f in chosen)
    assert all(c.licence.startswith('CC BY-NC') for c in fetched)
    assert len(catalogue.load_clips(cache_dir=tmp_path / 'cache', committed_only=True)) == \
        len(clips) - 2


def test_fetch_reads_a_git_directory(tmp_path):
    chosen = _bandai_entries()[0].file
    repo = tmp_path / 'repo'
    _fake_bandai(repo, [chosen])
    git = ['git', '-C', str(repo), '-c', 'user.name=t', '-c', 'user.email=t@t']
    subprocess.run([*git[:3], 'init', '-q'], check=True)
    subprocess.run([*git, 'add', '.'], check=True)
    subprocess.run([*git, 'commit', '-qm', 'x'], check=True)
    (repo / fetch.FETCH_SOURCES['bandai'].path(chosen)).unlink()   # only HEAD has it now
    res = fetch.fetch('bandai', src=str(repo / '.git'), dest=tmp_path / 'out')
    assert res.copied == [chosen]
    assert (tmp_path / 'out' / chosen).read_text().startswith('HIERARCHY')
    # the same through a (shallow, blob-less) clone of a URL
    res = fetch.fetch('bandai', src=repo.as_uri(), dest=tmp_path / 'out2')
    assert res.copied == [chosen]
    with pytest.raises(MocapError, match='cannot clone'):
        fetch.fetch('bandai', src=(tmp_path / 'nothing').as_uri(), dest=tmp_path / 'out3')


def test_fetch_rejects_unknown_sources(tmp_path):
    with pytest.raises(MocapError, match='unknown source'):
        fetch.fetch('nope', src=str(tmp_path))
    with pytest.raises(MocapError, match='neither'):
        fetch.fetch('bandai', src=str(tmp_path / 'missing'), dest=tmp_path / 'o')


def test_fetch_command_exit_status(tmp_path, capsys, monkeypatch):
    src = tmp_path / 'src'
    _fake_bandai(src, [_bandai_entries()[0].file])
    assert fetch.main(['bandai', '--from', str(src), '--cache', str(tmp_path / 'c')]) == 1
    out = capsys.readouterr()
    assert '1 clips copied' in out.out and 'missing in the source' in out.err
    monkeypatch.chdir(tmp_path)
    assert fetch.main(['bandai', '--from', str(tmp_path / 'none')]) == 2
    assert 'neither a folder' in capsys.readouterr().err
    assert not (tmp_path / 'data').exists()   # nothing written for a bad source
