"""The mocap catalogue: committed clips load on a fresh clone, fixed splits, no excluded clip."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from endeff_ros.synth.mocap import FAMILIES, SPLITS, catalogue
from endeff_ros.synth.mocap.clip import JOINT_INDEX as J
from endeff_ros.synth.mocap.fetch import EXCLUDED
from endeff_ros.synth.mocap.kin import MocapError


@pytest.fixture(scope='module')
def committed(tmp_path_factory):
    # an empty cache folder: only what the repository holds
    return catalogue.load_clips(cache_dir=tmp_path_factory.mktemp('empty'))


def _seg(p: np.ndarray, a: str, b: str) -> np.ndarray:
    return np.linalg.norm(p[:, J[a]] - p[:, J[b]], axis=1)


def stature(p: np.ndarray) -> float:
    """Pose-invariant height estimate (m): head and trunk segments, the mean leg, and 8 cm
    from the ankle joint to the sole."""
    trunk = sum(_seg(p, a, b) for a, b in (('head_top', 'head'), ('head', 'neck'),
                                             ('neck', 'chest'), ('chest', 'spine'),
                                             ('spine', 'pelvis')))
    legs = 0.5 * sum(_seg(p, f'{s}_hip', f'{s}_knee') + _seg(p, f'{s}_knee', f'{s}_ankle')
                     for s in 'lr')
    return float(np.median(trunk + legs)) + 0.08


def test_committed_clips_load_and_are_normalised(committed):
    by_source = Counter(c.source for c in committed)
    assert len(committed) >= 20 and by_source['deepmimic'] == len(committed)
    for c in committed:
        p = c.positions
        assert c.fps == 30.0 and len(p) >= 20, c.name
        assert 1.4 <= stature(p) <= 2.0, c.name
        assert p[0, J['pelvis'], 0] == pytest.approx(0.0, abs=1e-9)
        assert p[0, J['pelvis'], 2] == pytest.approx(0.0, abs=1e-9)
        assert p[0, J['l_hip'], 0] - p[0, J['r_hip'], 0] > 0.1, c.name
        feet = p[:, [J['l_ankle'], J['l_toe'], J['r_ankle'], J['r_toe']], 1]
        assert feet.min() == pytest.approx(0.0, abs=1e-9), c.name
        assert c.licence, c.name
        step = np.linalg.norm(np.diff(p, axis=0), axis=2).max() * c.fps
        assert step < 20.0, f'{c.name}: a joint jumps at {step:.1f} m/s'


def test_walks_go_forward_and_toes_point_forward(committed):
    # catches a mirrored skeleton or a wrong facing: people walk to their front (+z)
    walks = [c for c in committed if c.family == 'walk']
    assert walks
    for c in walks:
        p = c.positions
        assert p[-1, J['pelvis'], 2] - p[0, J['pelvis'], 2] > 0.5 * c.duration_s, c.name
        toe = np.median(p[:, J['l_toe'], 2] - p[:, J['l_ankle'], 2])
        assert toe > 0.03, c.name


def test_table_is_consistent():
    names = [e.name for e in catalogue.CLIPS]
    assert len(names) == len(set(names))
    for e in catalogue.CLIPS:
        assert e.family in FAMILIES and e.split in SPLITS and e.source in catalogue.SOURCES
    srcs = {e.source for e in catalogue.CLIPS}
    assert len(srcs) >= 4


def test_no_excluded_clip_anywhere():
    names = [e.name for e in catalogue.CLIPS]
    names += [p.name for p in catalogue.DATA_DIR.rglob('*')]
    for bad in ('01_01', '001_01', '01_01_cmu', 'cmu/1_01', 'test_mocapbank.bvh',
                'walk1_subject1.bvh'):
        assert EXCLUDED.search(bad), bad
    assert not [n for n in names if EXCLUDED.search(n)]


def test_splits_fixed_balanced_and_never_shared():
    for source in catalogue.SOURCES:
        count = Counter(e.split for e in catalogue.CLIPS if e.source == source)
        assert count['dev'] and count['test'], source
        assert abs(count['dev'] - count['test']) <= max(2, 0.1 * sum(count.values())), source
    fam = Counter((e.family, e.split) for e in catalogue.CLIPS)
    for f in {e.family for e in catalogue.CLIPS}:
        n = fam[(f, 'dev')] + fam[(f, 'test')]
        if n >= 2:
            assert fam[(f, 'dev')] and fam[(f, 'test')], f


def test_loaded_splits_are_the_tables(committed):
    table = {e.name: (e.family, e.split) for e in catalogue.CLIPS}
    assert {c.split for c in committed} == set(SPLITS)
    for c in committed:
        assert (c.family, c.split) == table[c.name]


def test_stats_add_up(committed):
    s = catalogue.stats(committed)
    assert s['clips'] == len(committed)
    assert sum(v['clips'] for v in s['splits'].values()) == len(committed)
    assert s['minutes'] == pytest.approx(sum(c.duration_s for c in committed) / 60, abs=0.01)
    assert catalogue.main(['--committed-only']) == 0


def test_missing_committed_file_is_a_clear_error(monkeypatch, tmp_path):
    monkeypatch.setattr(catalogue, 'DATA_DIR', tmp_path)
    with pytest.raises(MocapError, match='is missing'):
        catalogue.load_clips(committed_only=True)


def test_committed_data_is_small_and_has_notices():
    total = sum(p.stat().st_size for p in catalogue.DATA_DIR.rglob('*') if p.is_file())
    assert total < 15e6
    for source, src in catalogue.SOURCES.items():
        if src.committed:
            folder: Path = catalogue.DATA_DIR / source
            assert (folder / 'NOTICE.md').is_file()
            assert list(folder.glob('LICENSE*'))


def test_load_by_name(committed):
    want = [committed[3].name, committed[0].name]
    got = catalogue.load_clips(names=want, committed_only=True)
    assert [c.name for c in got] == [committed[0].name, committed[3].name]
    np.testing.assert_array_equal(got[1].positions, committed[3].positions)
    with pytest.raises(MocapError, match='unknown clips'):
        catalogue.load_clips(names=['deepmimic/nope'])


def test_looped_cycles_are_long_and_smooth(committed):
    looped = {c.name: c for c in catalogue.load_clips(committed_only=True, loop_s=6.0)}
    for c in committed:
        lc = looped[c.name]
        step = np.linalg.norm(np.diff(c.positions, axis=0), axis=2).max()
        lstep = np.linalg.norm(np.diff(lc.positions, axis=0), axis=2).max()
        if lc.duration_s > c.duration_s:
            assert lc.duration_s >= 6.0 - 1 / 30, c.name
            # the seam between cycles is no bigger a jump than the clip's own motion
            assert lstep < 1.2 * step + 0.01, c.name
        else:
            np.testing.assert_array_equal(lc.positions, c.positions)
    walk = looped['deepmimic/humanoid3d_walk'].positions
    assert walk[-1, J['pelvis'], 2] > 4.0   # 6 s of walking at about 1 m/s, straight on
    assert abs(walk[-1, J['pelvis'], 0]) < 0.15 * walk[-1, J['pelvis'], 2]
    assert sum(lc.duration_s > c.duration_s for c, lc in
               zip(committed, looped.values(), strict=True)) >= 6


def test_clips_are_cached_and_read_only(committed):
    again = catalogue.load_clips(committed_only=True)
    assert again[0] is committed[0]
    with pytest.raises(ValueError):
        committed[0].positions[0, 0, 0] = 1.0
