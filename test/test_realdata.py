"""Real hand-labelled frames: exact depth round trip, recovered intrinsics, labels, bags."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np
import pytest

from endeff_ros.attributes import ATTRIBUTES_KEY, custom_data
from endeff_ros.bag.reader import BagReader
from endeff_ros.realdata import SOURCES, build_bag, source_labels
from endeff_ros.realdata.__main__ import main as realdata_main
from endeff_ros.realdata.labels import RADIUS_M, LabelError, make_label, read_labels
from endeff_ros.realdata.sources import (
    SourceError,
    lzf_decompress,
    read_five_people,
    read_pcd,
    read_skeltrack,
)

FIVE = SOURCES['five_people'].folder / 'five_people.pcd'


def test_skeltrack_frames_are_the_raw_millimetres() -> None:
    files = SOURCES['skeltrack'].files()
    assert len(files) == 12
    for path in files:
        raw = np.frombuffer(gzip.decompress(path.read_bytes()), '<u2')
        frame = read_skeltrack(path)
        assert frame.depth_mm.shape == (480, 640)
        assert np.array_equal(frame.depth_mm.reshape(-1), raw)
        valid = frame.depth_mm[frame.depth_mm > 0]
        # A person about 1 m away in millimetres (not metres, not raw 11-bit disparity).
        assert 600 < np.median(valid) < 2000 and valid.max() < 10000


def test_five_people_is_organised_and_intrinsics_reproject_the_cloud() -> None:
    header, fields = read_pcd(FIVE)
    assert (header['WIDTH'], header['HEIGHT'], header['FIELDS']) == ('640', '480', 'x y z rgba')
    frame, grid = read_five_people(FIVE)
    z = grid['z'].astype(np.float64)
    ok = np.isfinite(z)
    assert ok.sum() > 100_000
    # Depth: whole millimetres, reproduced exactly (the cloud's z is mm * 0.001f).
    assert np.array_equal(frame.depth_mm > 0, ok)
    np.testing.assert_array_equal(frame.depth_mm[ok].astype(np.float32) * np.float32(0.001),
                                  grid['z'][ok])
    intr = frame.intrinsics
    v, u = np.indices(z.shape)
    x_rep = (u[ok] - intr.cx) * z[ok] / intr.fx
    y_rep = (v[ok] - intr.cy) * z[ok] / intr.fy
    assert np.abs(x_rep - grid['x'][ok]).max() < 1e-3
    assert np.abs(y_rep - grid['y'][ok]).max() < 1e-3
    rgba = grid['rgba'][ok]
    np.testing.assert_array_equal(frame.rgb[ok][:, 0], (rgba >> 16) & 255)
    np.testing.assert_array_equal(frame.rgb[ok][:, 2], rgba & 255)


def test_lzf_decoder_and_bad_sources(tmp_path: Path) -> None:
    # Literal 'abc', then a back-reference of length 5 at distance 3 (overlapping: 'abcab').
    data = bytes([2]) + b'abc' + bytes([(3 << 5) | 0, 2])
    assert lzf_decompress(data, 8) == b'abcabcab'
    with pytest.raises(SourceError, match='decompressed to 8 bytes'):
        lzf_decompress(data, 9)
    with pytest.raises(SourceError, match='truncated'):
        lzf_decompress(data[:-1], 8)
    bad = tmp_path / 'depth-data-1.gz'
    bad.write_bytes(gzip.compress(b'\0' * 100))
    with pytest.raises(SourceError, match='100 bytes'):
        read_skeltrack(bad)
    pcd = tmp_path / 'a.pcd'
    pcd.write_bytes(b'VERSION 0.7\nFIELDS x\nSIZE 4\nTYPE F\nCOUNT 1\nPOINTS 1\nDATA ascii\n0\n')
    with pytest.raises(SourceError, match='ascii'):
        read_pcd(pcd)
    # Uncompressed binary PCD: points stored as packed records.
    rec = np.array([(1.5, 7), (-2.0, 9)], dtype=[('x', '<f4'), ('rgba', '<u4')])
    pcd.write_bytes(b'# comment\nVERSION 0.7\nFIELDS x rgba\nSIZE 4 4\nTYPE F U\nCOUNT 1 1\n'
                    b'WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n' + rec.tobytes())
    _, fields = read_pcd(pcd)
    assert fields['x'].tolist() == [1.5, -2.0] and fields['rgba'].tolist() == [7, 9]


@pytest.mark.parametrize('name', list(SOURCES))
def test_labels_inside_image_and_behind_the_surface(name: str) -> None:
    source = SOURCES[name]
    frames = {f.name: f for f in source.frames()}
    stored = read_labels(source.labels_path)
    lifted = source_labels(source, list(frames.values()))
    assert set(lifted) <= set(frames) and lifted
    for fname, labels in lifted.items():
        depth = frames[fname].depth_mm
        intr = frames[fname].intrinsics
        ids = [lab.id for lab in labels]
        assert len(set(ids)) == len(ids), fname
        for lab, raw in zip(labels, stored[fname], strict=True):
            assert 0 <= lab.u < intr.width and 0 <= lab.v < intr.height
            surface = depth[lab.v, lab.u] / 1000.0
            # On or behind the person's surface: the pixel's depth is at most the label's z.
            assert 0.0 < surface <= lab.xyz[2], (fname, lab.id)
            assert lab.xyz[2] == pytest.approx(lab.depth_m + RADIUS_M[lab.kind])
            # The committed file is up to date with its picks (re-run `label` after edits).
            assert raw['kind'] == lab.kind
            np.testing.assert_allclose(raw['xyz'], lab.xyz, atol=1e-4)
            # Projects back onto its pixel.
            x, y, z = lab.xyz
            assert x / z * intr.fx + intr.cx == pytest.approx(lab.u, abs=0.01)
            assert y / z * intr.fy + intr.cy == pytest.approx(lab.v, abs=0.01)


def test_make_label_rejects_bad_picks() -> None:
    frame = SOURCES['skeltrack'].frames()[0]
    with pytest.raises(LabelError, match='is a hand'):
        make_label('f', frame.depth_mm, frame.intrinsics, {'id': 1, 'kind': 'head', 'u': 10,
                                                           'v': 10, 'r_px': 3})
    with pytest.raises(LabelError, match='outside the image'):
        make_label('f', frame.depth_mm, frame.intrinsics, {'id': 0, 'u': 640, 'v': 10,
                                                           'r_px': 3})
    with pytest.raises(LabelError, match='no depth reading'):
        make_label('f', frame.depth_mm, frame.intrinsics, {'id': 0, 'u': 2, 'v': 2, 'r_px': 2})


@pytest.mark.parametrize(('name', 'storage', 'repeat'),
                         [('skeltrack', 'mcap', 1), ('five_people', 'sqlite3', 2)])
def test_bag_holds_depth_and_labels_at_the_depth_stamps(tmp_path: Path, name: str, storage: str,
                                                       repeat: int) -> None:
    source = SOURCES[name]
    frames = source.frames()
    labels = source_labels(source, frames)
    n = build_bag(source, tmp_path / name, storage=storage, repeat=repeat)
    assert n == len(frames) * repeat
    with BagReader(tmp_path / name) as bag:
        attributes = json.loads(custom_data(bag.reader)[ATTRIBUTES_KEY])
        records = list(bag.frames())
        assert bag.stats.gt_matched == n
    assert attributes['people'] >= 1 and attributes['sensor'] == 'kinect_v1'
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
        assert gt is not None
        np.testing.assert_allclose(gt, want, atol=1e-6)


def test_cli_build_and_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert realdata_main(['build', str(tmp_path / 'out'), '--sources', 'five_people']) == 0
    assert (tmp_path / 'out' / 'five_people' / 'metadata.yaml').exists()
    assert realdata_main(['build', str(tmp_path / 'out'), '--sources', 'nope']) == 1
    assert "unknown source 'nope'" in capsys.readouterr().err
