"""Real hand-labelled frames: readers, intrinsics fit, labels, bags and the fetch step.

The real frames are never committed (they are fetched into a local cache), so everything here
runs on synthetic stand-ins written in the sources' formats: a Skeltrack-style 640 x 480
little-endian uint16 millimetre frame (gzip) and organised PCD clouds (``DATA binary`` and
``binary_compressed``). The committed labels are checked for their structure.
"""

from __future__ import annotations

import dataclasses
import gzip
import hashlib
import json
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from endeff_ros.attributes import ATTRIBUTES_KEY, custom_data
from endeff_ros.bag.reader import BagReader
from endeff_ros.core.types import Intrinsics
from endeff_ros.realdata import DATA_DIR, SOURCES, Source, build_bag, source_labels
from endeff_ros.realdata import fetch as rfetch
from endeff_ros.realdata.__main__ import main as realdata_main
from endeff_ros.realdata.labels import RADIUS_M, LabelError, lift, make_label, read_labels
from endeff_ros.realdata.sources import (
    HEIGHT,
    SKELTRACK_INTRINSICS,
    WIDTH,
    SourceError,
    lzf_decompress,
    read_five_people,
    read_pcd,
    read_skeltrack,
)
from endeff_ros.scoring import PERSON_KINDS

PCD_INTRINSICS = Intrinsics(531.25, 528.5, 322.75, 236.5, WIDTH, HEIGHT)


def _depth(seed: int, base: int = 900, holes: bool = True) -> np.ndarray:
    """(480, 640) uint16 mm: a ramp plus noise, values above 255 (so byte order matters),
    with a block of holes (0) in the top-left corner."""
    rng = np.random.default_rng(seed)
    v, u = np.indices((HEIGHT, WIDTH))
    depth = (base + u + v // 2 + rng.integers(0, 8, (HEIGHT, WIDTH))).astype(np.uint16)
    if holes:
        depth[:40, :60] = 0
    return depth


def _lzf_literals(data: bytes) -> bytes:
    """LZF of literal runs only (control byte ``length - 1``, then up to 32 bytes): valid LZF
    that any decoder must reproduce."""
    full = len(data) // 32
    runs = np.frombuffer(data[:full * 32], np.uint8).reshape(full, 32)
    out = np.hstack([np.full((full, 1), 31, np.uint8), runs]).tobytes()
    rest = data[full * 32:]
    return out + (bytes([len(rest) - 1]) + rest if rest else b'')


def _write_pcd(path: Path, depth_mm: np.ndarray, rgba: np.ndarray, intr: Intrinsics,
               mode: str = 'binary_compressed') -> None:
    """An organised cloud as PCL writes it: z = mm * 0.001f, NaN where there is no reading."""
    h, w = depth_mm.shape
    z = np.where(depth_mm > 0, depth_mm.astype(np.float32) * np.float32(0.001), np.nan)
    z = z.astype(np.float32)
    v, u = np.indices((h, w))
    x = ((u - intr.cx) * z / intr.fx).astype(np.float32)
    y = ((v - intr.cy) * z / intr.fy).astype(np.float32)
    header = (f'# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgba\n'
              f'SIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH {w}\nHEIGHT {h}\n'
              f'VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {h * w}\nDATA {mode}\n').encode()
    cols = [x.ravel(), y.ravel(), z.ravel(), rgba.astype('<u4').ravel()]
    if mode == 'binary':
        rec = np.empty(h * w, [('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('rgba', '<u4')])
        for name, col in zip(('x', 'y', 'z', 'rgba'), cols, strict=True):
            rec[name] = col
        body = rec.tobytes()
    else:
        raw = b''.join(c.astype(c.dtype.newbyteorder('<')).tobytes() for c in cols)
        comp = _lzf_literals(raw)
        body = struct.pack('<II', len(comp), len(raw)) + comp
    path.write_bytes(header + body)


def _rgba(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 2 ** 32, (HEIGHT, WIDTH), dtype=np.uint32)


# -- readers ------------------------------------------------------------------------------------


def test_skeltrack_reader_reads_little_endian_millimetres(tmp_path: Path) -> None:
    depth = _depth(1)
    (tmp_path / 'depth-data-7').write_bytes(depth.astype('<u2').tobytes())
    (tmp_path / 'depth-data-7.gz').write_bytes(gzip.compress(depth.astype('<u2').tobytes()))
    for name in ('depth-data-7', 'depth-data-7.gz'):
        frame = read_skeltrack(tmp_path / name)
        assert frame.name == 'depth-data-7'
        np.testing.assert_array_equal(frame.depth_mm, depth)
        assert frame.intrinsics == SKELTRACK_INTRINSICS
        assert frame.rgb.shape == (HEIGHT, WIDTH, 3)
        assert not frame.rgb[:40, :60].any() and frame.rgb[depth > 0].min() >= 40
        # Near is bright: the grey falls along the depth ramp.
        assert frame.rgb[300, 100, 0] > frame.rgb[300, 600, 0]
    bad = tmp_path / 'depth-data-1.gz'
    bad.write_bytes(gzip.compress(b'\0' * 100))
    with pytest.raises(SourceError, match='100 bytes'):
        read_skeltrack(bad)


@pytest.mark.parametrize('mode', ['binary', 'binary_compressed'])
def test_pcd_reader_round_trip_and_intrinsics_fit(tmp_path: Path, mode: str) -> None:
    depth, rgba = _depth(2, base=1800), _rgba(3)
    path = tmp_path / 'cloud.pcd'
    _write_pcd(path, depth, rgba, PCD_INTRINSICS, mode)
    header, fields = read_pcd(path)
    assert (header['WIDTH'], header['HEIGHT'], header['DATA']) == ('640', '480', mode)
    frame, grid = read_five_people(path)
    np.testing.assert_array_equal(frame.depth_mm, depth)  # whole millimetres, exactly
    np.testing.assert_array_equal(grid['rgba'], rgba)
    np.testing.assert_array_equal(frame.rgb[..., 0], (rgba >> 16) & 255)
    np.testing.assert_array_equal(frame.rgb[..., 1], (rgba >> 8) & 255)
    np.testing.assert_array_equal(frame.rgb[..., 2], rgba & 255)
    intr = frame.intrinsics
    got = np.array([intr.fx, intr.fy, intr.cx, intr.cy])
    want = np.array([PCD_INTRINSICS.fx, PCD_INTRINSICS.fy, PCD_INTRINSICS.cx, PCD_INTRINSICS.cy])
    np.testing.assert_allclose(got, want, atol=2e-3)
    ok = depth > 0
    v, u = np.indices(depth.shape)
    z = grid['z'][ok].astype(np.float64)
    assert np.abs((u[ok] - intr.cx) * z / intr.fx - grid['x'][ok]).max() < 1e-4


def test_lzf_decoder_and_bad_sources(tmp_path: Path) -> None:
    # Literal 'abc', then a back-reference of length 5 at distance 3 (overlapping: 'abcab').
    data = bytes([2]) + b'abc' + bytes([(3 << 5) | 0, 2])
    assert lzf_decompress(data, 8) == b'abcabcab'
    with pytest.raises(SourceError, match='decompressed to 8 bytes'):
        lzf_decompress(data, 9)
    with pytest.raises(SourceError, match='truncated'):
        lzf_decompress(data[:-1], 8)
    payload = bytes(range(256)) * 3 + b'xyz'
    assert lzf_decompress(_lzf_literals(payload), len(payload)) == payload
    pcd = tmp_path / 'a.pcd'
    pcd.write_bytes(b'VERSION 0.7\nFIELDS x\nSIZE 4\nTYPE F\nCOUNT 1\nPOINTS 1\nDATA ascii\n0\n')
    with pytest.raises(SourceError, match='ascii'):
        read_pcd(pcd)
    pcd.write_bytes(b'VERSION 0.7\nFIELDS x\nSIZE 4\nTYPE F\nCOUNT 1\nWIDTH 1\nHEIGHT 1\n'
                    b'POINTS 1\nDATA binary\n\0\0\0\0')
    with pytest.raises(SourceError, match='organised cloud with x y z rgba'):
        read_five_people(pcd)


# -- labels -------------------------------------------------------------------------------------


@pytest.mark.parametrize('name', list(SOURCES))
def test_committed_labels_structure(name: str) -> None:
    source = SOURCES[name]
    stored = read_labels(source.labels_path)
    frame_names = {f.removesuffix('.gz').removesuffix('.pcd') for f in source.files}
    assert stored and set(stored) <= frame_names
    rows = []
    for fname, labels in stored.items():
        ids = [int(lab['id']) for lab in labels]
        assert len(set(ids)) == len(ids), fname
        for lab in labels:
            kind = PERSON_KINDS[lab['id'] % len(PERSON_KINDS)]
            assert lab['kind'] == kind, (fname, lab['id'])
            assert 0 <= lab['u'] < WIDTH and 0 <= lab['v'] < HEIGHT and lab['r_px'] > 0
            xyz = np.asarray(lab['xyz'], np.float64)
            assert xyz.shape == (3,) and np.isfinite(xyz).all() and lab['depth_m'] > 0
            # The centre behind the surface by the part's radius (both stored to 0.1 mm).
            assert xyz[2] == pytest.approx(lab['depth_m'] + RADIUS_M[kind], abs=2e-4)
            rows.append((lab['u'], lab['v'], *xyz))
    # All labels of a source lie on the viewing rays of their pixels through one pinhole.
    u, v, x, y, z = np.array(rows, np.float64).T
    for pix, ratio in ((u, x / z), (v, y / z)):
        slope, offset = np.polyfit(ratio, pix, 1)
        assert np.abs(slope * ratio + offset - pix).max() < 0.05
    if name == 'skeltrack':
        intr = SKELTRACK_INTRINSICS
        np.testing.assert_allclose(x / z * intr.fx + intr.cx, u, atol=0.05)
        np.testing.assert_allclose(y / z * intr.fy + intr.cy, v, atol=0.05)


def _labelled_frame(tmp_path: Path) -> tuple[Source, Path, np.ndarray]:
    """A Skeltrack-style frame: wall at 3 m, a head disk (r 25 px) at about 1.5 m, a hand disk
    (r 12 px) at about 1.1 m; its labels file; the source reading them from ``tmp_path``."""
    rng = np.random.default_rng(4)
    depth = np.full((HEIGHT, WIDTH), 3000, np.uint16)
    v, u = np.indices(depth.shape)
    head = (u - 300) ** 2 + (v - 200) ** 2 <= 25 ** 2
    hand = (u - 420) ** 2 + (v - 260) ** 2 <= 12 ** 2
    depth[head] = 1500 + rng.integers(-6, 7, int(head.sum()))
    depth[hand] = 1100 + rng.integers(-4, 5, int(hand.sum()))
    depth[:40, :60] = 0
    cache = tmp_path / 'cache'
    (cache / 'skeltrack').mkdir(parents=True)
    (cache / 'skeltrack' / 'depth-data-5.gz').write_bytes(
        gzip.compress(depth.astype('<u2').tobytes()))
    (tmp_path / 'labels.yaml').write_text(
        'frames:\n- frame: depth-data-5\n  labels:\n'
        '  - {id: 0, kind: head, u: 300, v: 200, r_px: 35}\n'
        '  - {id: 2, u: 420, v: 260, r_px: 8, note: fist}\n')
    source = dataclasses.replace(SOURCES['skeltrack'], files=('depth-data-5.gz',),
                                 labels_dir=tmp_path)
    return source, cache, depth


def test_labels_lift_the_part_behind_its_surface(tmp_path: Path) -> None:
    source, cache, depth = _labelled_frame(tmp_path)
    frame = source.frames(cache)[0]
    labels = source_labels(source, [frame])['depth-data-5']
    v, u = np.indices(depth.shape)
    head, hand = labels
    # The head pick's disk (35 px) reaches the wall: only the head's own pixels count.
    head_px = depth[((u - 300) ** 2 + (v - 200) ** 2 <= 25 ** 2)]
    assert head.depth_m == pytest.approx(np.median(head_px) / 1000.0)
    hand_px = depth[((u - 420) ** 2 + (v - 260) ** 2 <= 8 ** 2)]
    assert hand.depth_m == pytest.approx(np.median(hand_px) / 1000.0)
    assert (head.kind, hand.kind, hand.note) == ('head', 'hand', 'fist')
    intr = SKELTRACK_INTRINSICS
    assert head.xyz == pytest.approx(lift(intr, 300, 200, head.depth_m + RADIUS_M['head']))
    assert hand.xyz == pytest.approx(lift(intr, 420, 260, hand.depth_m + RADIUS_M['hand']))
    (tmp_path / 'labels.yaml').write_text('frames:\n- frame: depth-data-6\n  labels: []\n')
    with pytest.raises(LabelError, match="frame 'depth-data-6' is not a frame of skeltrack"):
        source_labels(source, [frame])


def test_make_label_rejects_bad_picks(tmp_path: Path) -> None:
    source, cache, _ = _labelled_frame(tmp_path)
    frame = source.frames(cache)[0]
    d, intr = frame.depth_mm, frame.intrinsics
    with pytest.raises(LabelError, match='is a hand'):
        make_label('f', d, intr, {'id': 1, 'kind': 'head', 'u': 10, 'v': 100, 'r_px': 3})
    with pytest.raises(LabelError, match='outside the image'):
        make_label('f', d, intr, {'id': 0, 'u': 640, 'v': 10, 'r_px': 3})
    with pytest.raises(LabelError, match='no depth reading'):
        make_label('f', d, intr, {'id': 0, 'u': 2, 'v': 2, 'r_px': 2})
    with pytest.raises(LabelError, match='needs integer id'):
        make_label('f', d, intr, {'id': 0, 'u': 2, 'v': 2})


# -- bags ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(('name', 'storage', 'repeat'),
                         [('skeltrack', 'mcap', 1), ('five_people', 'sqlite3', 2)])
def test_bag_holds_depth_and_labels_at_the_depth_stamps(tmp_path: Path, name: str, storage: str,
                                                       repeat: int) -> None:
    folder = tmp_path / 'cache' / name
    folder.mkdir(parents=True)
    if name == 'skeltrack':
        files = ('depth-data-3.gz', 'depth-data-12.gz')
        for k, f in enumerate(files):
            (folder / f).write_bytes(gzip.compress(_depth(10 + k).astype('<u2').tobytes()))
    else:
        files = ('cloud.pcd',)
        _write_pcd(folder / 'cloud.pcd', _depth(12, base=1800), _rgba(13), PCD_INTRINSICS)
    stems = [f.removesuffix('.gz').removesuffix('.pcd') for f in files]
    picks = ''.join(f'- frame: {s}\n  labels:\n  - {{id: 0, u: {300 + k}, v: 200, r_px: 5}}\n'
                    f'  - {{id: 4, u: 100, v: {400 - k}, r_px: 4}}\n'
                    for k, s in enumerate(stems))
    (tmp_path / 'labels.yaml').write_text('frames:\n' + picks)
    source = dataclasses.replace(SOURCES[name], files=files, labels_dir=tmp_path)
    frames = source.frames(tmp_path / 'cache')
    labels = source_labels(source, frames)
    n = build_bag(source, tmp_path / name, cache=tmp_path / 'cache', storage=storage,
                  repeat=repeat)
    assert n == len(frames) * repeat
    with BagReader(tmp_path / name) as bag:
        attributes = json.loads(custom_data(bag.reader)[ATTRIBUTES_KEY])
        records = list(bag.frames())
        assert bag.stats.gt_matched == n
    assert attributes == dict(SOURCES[name].attributes,
                              **({'repeat': repeat} if repeat > 1 else {}))
    assert len(records) == n
    stamps = [frame.stamp_ns for frame, _ in records]
    assert stamps == sorted(set(stamps))
    for k, (frame, gt) in enumerate(records):
        src = frames[k // repeat]
        mm = np.where(np.isfinite(frame.depth), np.round(frame.depth * 1000.0), 0)
        np.testing.assert_array_equal(mm, src.depth_mm)  # exact round trip
        assert frame.color is not None and np.array_equal(frame.color, src.rgb)
        assert frame.intrinsics.fx == src.intrinsics.fx
        want = np.array(sorted((lab.id, *lab.xyz) for lab in labels[src.name]))[:, 1:]
        assert gt is not None and len(gt) == 2
        np.testing.assert_allclose(gt, want, atol=1e-6)


# -- fetch --------------------------------------------------------------------------------------


def _fake_skeltrack(root: Path) -> dict[str, bytes]:
    """A folder laid out like Skeltrack's repository (the 12 frames, one more, COPYING)."""
    res = root / 'tests' / 'resources'
    res.mkdir(parents=True)
    raws = {}
    for k, f in enumerate((*SOURCES['skeltrack'].files, 'depth-data-99.gz')):
        raws[f] = _depth(20 + k).astype('<u2').tobytes()
        (res / f.removesuffix('.gz')).write_bytes(raws[f])
    (root / 'COPYING').write_text('GNU LESSER GENERAL PUBLIC LICENSE (stand-in)\n')
    return raws


def _fake_pcl(root: Path) -> bytes:
    (root / 'test').mkdir(parents=True)
    _write_pcd(root / 'test' / 'five_people.pcd', _depth(30, base=1800, holes=False), _rgba(31),
               PCD_INTRINSICS)
    (root / 'LICENSE.txt').write_text('Software License Agreement (BSD License) (stand-in)\n')
    return (root / 'test' / 'five_people.pcd').read_bytes()


def test_fetch_copies_the_selection_gzipped_with_licence_and_notice(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for name, source in SOURCES.items():  # every frame has the hash of its labelled version
        assert set(rfetch.FETCH_SOURCES[name].sha256) == set(source.files)
    raws = _fake_skeltrack(tmp_path / 'src')
    cache = tmp_path / 'cache'
    res = rfetch.fetch('skeltrack', src=str(tmp_path / 'src'), cache=cache)
    files = list(SOURCES['skeltrack'].files)
    assert res.copied == files and not res.missing
    assert res.changed == files  # stand-ins are not the labelled frames
    assert sorted(p.name for p in (cache / 'skeltrack').iterdir()) == \
        sorted([*files, 'COPYING', 'NOTICE.md'])
    for f in files:
        assert gzip.decompress((cache / 'skeltrack' / f).read_bytes()) == raws[f]
        np.testing.assert_array_equal(read_skeltrack(cache / 'skeltrack' / f).depth_mm.ravel(),
                                      np.frombuffer(raws[f], '<u2'))
    assert (cache / 'skeltrack' / 'COPYING').read_text().startswith('GNU LESSER')
    assert (cache / 'skeltrack' / 'NOTICE.md').read_text() == \
        (DATA_DIR / 'skeltrack' / 'NOTICE.md').read_text()
    # Same content as labelled: nothing reported; fetching again gives the same bytes.
    before = (cache / 'skeltrack' / files[0]).read_bytes()
    fs = rfetch.FETCH_SOURCES['skeltrack']
    monkeypatch.setitem(rfetch.FETCH_SOURCES, 'skeltrack', dataclasses.replace(
        fs, sha256={f: hashlib.sha256(raws[f]).hexdigest() for f in files}))
    res = rfetch.fetch('skeltrack', src=str(tmp_path / 'src'), cache=cache)
    assert res.copied == files and not res.changed
    assert (cache / 'skeltrack' / files[0]).read_bytes() == before
    (tmp_path / 'src' / 'COPYING').unlink()
    (tmp_path / 'src' / 'tests' / 'resources' / files[3].removesuffix('.gz')).unlink()
    res = rfetch.fetch('skeltrack', src=str(tmp_path / 'src'), cache=tmp_path / 'c2')
    assert res.missing == ['COPYING', f'tests/resources/{files[3].removesuffix(".gz")}']
    assert len(res.copied) == 11


def test_fetch_reads_a_git_repository(tmp_path: Path) -> None:
    repo = tmp_path / 'repo'
    raw = _fake_pcl(repo)
    git = ['git', '-C', str(repo), '-c', 'user.name=t', '-c', 'user.email=t@t']
    subprocess.run([*git[:3], 'init', '-q'], check=True)
    subprocess.run([*git, 'add', '.'], check=True)
    subprocess.run([*git, 'commit', '-qm', 'x'], check=True)
    (repo / 'test' / 'five_people.pcd').unlink()  # only HEAD has it now
    for k, src in enumerate((str(repo / '.git'), repo.as_uri())):  # git dir; URL (clone)
        cache = tmp_path / f'cache{k}'
        res = rfetch.fetch('five_people', src=src, cache=cache)
        assert res.copied == ['five_people.pcd'] and not res.missing
        assert res.changed == ['five_people.pcd']
        assert (cache / 'five_people' / 'five_people.pcd').read_bytes() == raw
        assert (cache / 'five_people' / 'LICENSE.txt').read_text().startswith('Software')
        frame = SOURCES['five_people'].frames(cache)[0]
        np.testing.assert_array_equal(frame.depth_mm, _depth(30, base=1800, holes=False))
    with pytest.raises(SourceError, match='cannot clone'):
        rfetch.fetch('five_people', src=(tmp_path / 'nothing').as_uri(), cache=tmp_path / 'c')
    with pytest.raises(SourceError, match='unknown source'):
        rfetch.fetch('nope', src=str(repo), cache=tmp_path / 'c')


def test_cli_fetch_build_and_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                    monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    # No cache: one line naming the fetch command.
    assert realdata_main(['build', 'out']) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1
    assert 'run `python -m endeff_ros.realdata fetch skeltrack` first' in err
    assert realdata_main(['render', 'png', '--cache', 'c']) == 1
    assert 'fetch skeltrack --cache c`' in capsys.readouterr().err
    # A bad source: status 2, nothing written.
    assert realdata_main(['fetch', 'skeltrack', '--from', str(tmp_path / 'none')]) == 2
    assert 'neither a folder' in capsys.readouterr().err
    assert not (tmp_path / 'data').exists()
    # A stand-in source: copied, reported as differing from the labelled version (status 1).
    _fake_pcl(tmp_path / 'pcl')
    assert realdata_main(['fetch', 'five_people', '--from', 'pcl', '--cache', 'c']) == 1
    out = capsys.readouterr()
    assert '1 of 1 frame files copied to c/five_people' in out.out
    assert 'differ from the labelled version' in out.err
    # build reads the cache and the committed labels (the stand-in has depth everywhere).
    assert realdata_main(['build', 'out', '--sources', 'five_people', '--cache', 'c']) == 0
    assert (tmp_path / 'out' / 'five_people' / 'metadata.yaml').exists()
    with BagReader(tmp_path / 'out' / 'five_people') as bag:
        gt = [g for _, g in bag.frames()]
    n_labels = sum(len(v) for v in read_labels(SOURCES['five_people'].labels_path).values())
    assert len(gt) == 1 and gt[0] is not None and len(gt[0]) == n_labels
    assert realdata_main(['build', 'out', '--sources', 'nope', '--cache', 'c']) == 1
    assert "unknown source 'nope'" in capsys.readouterr().err


def test_still_bags_play_each_frame_still_with_fresh_sensor_noise(tmp_path: Path) -> None:
    """``build --still N``: one bag per frame, its N copies read again with noise (never
    bit-identical, the scene itself unmoved) and the same labels, attribute motion=still."""
    source, cache, depth = _labelled_frame(tmp_path)
    path = tmp_path / 'still'
    n = build_bag(source, path, cache=cache, repeat=6, frame=0, noise=True)
    assert n == 6
    with BagReader(path) as bag:
        attributes = json.loads(custom_data(bag.reader)[ATTRIBUTES_KEY])
        records = list(bag.frames())
    assert attributes['motion'] == 'still' and attributes['repeat'] == 6
    mm = [np.where(np.isfinite(f.depth), f.depth * 1000.0, 0.0) for f, _ in records]
    read = depth > 0
    for a, b in zip(mm, mm[1:]):
        assert not np.array_equal(a, b)  # each copy read again
    stack = np.stack(mm)
    dropped = (stack == 0) & read
    assert 0.003 < dropped.mean() < 0.03  # about 1 % of the readings
    mean = np.where(dropped, np.nan, stack)
    rel = np.nanmean(mean, axis=0)[read] / depth[read] - 1.0
    assert abs(float(np.mean(rel))) < 5e-4  # unbiased: the scene did not move
    assert 0.001 < float(np.nanstd(mean[:, read] / depth[read] - 1.0)) < 0.006
    gts = [gt for _, gt in records]
    assert all(np.array_equal(g, gts[0]) for g in gts)
    with pytest.raises(ValueError, match='frames 0-0'):
        build_bag(source, path, cache=cache, repeat=2, frame=3)


def test_a_frame_played_still_is_scored_as_without_the_background(tmp_path: Path) -> None:
    """The real-frame pipeline on a still bag of a person (a Skeltrack-style frame painted with
    the background tests' person, head and raised hand labelled): with the defaults the
    labels are found in the same copies as with the background off (the static background never
    hides what is in view from the first frame and holds end-effectors)."""
    from test_background import add_person, room

    from endeff_ros.core.params import EndeffParams
    from endeff_ros.evaluate import evaluate_bag

    z = room()
    add_person(z, 0.0, 1.0)
    depth = np.where(np.isfinite(z) & (z < 3.9), np.round(z * 1000.0), 0).astype(np.uint16)
    cache = tmp_path / 'cache'
    (cache / 'skeltrack').mkdir(parents=True)
    (cache / 'skeltrack' / 'depth-data-7.gz').write_bytes(
        gzip.compress(depth.astype('<u2').tobytes()))
    body = (depth > 0) & (depth < 3000)
    rows, cols = np.nonzero(body)
    top = rows < rows.min() + 20  # the head's upper part
    v_head, u_head = int(np.mean(rows[top])), int(np.mean(cols[top]))
    right = cols > cols.max() - 12  # the raised right hand's end
    v_hand, u_hand = int(np.mean(rows[right])), int(np.mean(cols[right]))
    (tmp_path / 'labels.yaml').write_text(
        'frames:\n- frame: depth-data-7\n  labels:\n'
        f'  - {{id: 0, kind: head, u: {u_head}, v: {v_head}, r_px: 8}}\n'
        f'  - {{id: 2, u: {u_hand}, v: {v_hand}, r_px: 6}}\n')
    source = dataclasses.replace(SOURCES['skeltrack'], files=('depth-data-7.gz',),
                                 labels_dir=tmp_path)
    path = tmp_path / 'still'
    build_bag(source, path, cache=cache, repeat=12, frame=0, noise=True)
    recalls = {}
    for background in (True, False):
        result = evaluate_bag(path, params=EndeffParams(background=background))
        recalls[background] = result.recalls['temporal']
    assert np.mean(recalls[False]) > 0.2
    assert recalls[True] == recalls[False]
    hidden = evaluate_bag(path, params=EndeffParams(background_keep_initial=False))
    assert max(hidden.recalls['temporal'][-4:]) == 0.0  # the test can fail
