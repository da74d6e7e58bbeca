"""Real, hand-labelled Kinect v1 depth frames of people as benchmark bags.

Two public sources; only our hand labels and the sources' notices are committed, under
``data/<source>/`` (``labels.yaml``, ``NOTICE.md``). The raw frames are copied from the
sources' repositories into a local cache (default ``data/realdata-cache/<source>/``, beside
the source's licence file) by :mod:`endeff_ros.realdata.fetch`:

- ``skeltrack``: the 12 depth frames of Skeltrack's tests (one person facing the camera at
  about 1.2 m, upper body; two frames show a second person behind), LGPL-3.0;
- ``five_people``: PCL's ``test/five_people.pcd``, an organised cloud with colour of five
  people walking away from the camera (1.8-3.5 m), BSD-3-Clause.

:func:`build_bags` writes one bag per source in the benchmark-bag form (colour ``rgb8``, a grey
rendering of the depth for Skeltrack; depth ``16UC1`` millimetres, exactly the source's
values; camera info; the hand labels of ``data/<source>/labels.yaml`` as ground truth at the
depth stamps) and records the source's attributes in the bag metadata
(:data:`endeff_ros.attributes.ATTRIBUTES_KEY`). Bags are generated, never committed::

    python -m endeff_ros.realdata fetch skeltrack
    python -m endeff_ros.realdata fetch five_people
    python -m endeff_ros.realdata build data/real
    endeff eval data/real

See ``docs/real-frames.md`` for the sources, the labelling method and the scores.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from endeff_ros.attributes import ATTRIBUTES_KEY
from endeff_ros.realdata.labels import Label, LabelError, gt_arrays, make_label, read_labels
from endeff_ros.realdata.sources import (
    RealFrame,
    SourceError,
    read_five_people,
    read_skeltrack,
)

DATA_DIR = Path(__file__).resolve().parent / 'data'
DEFAULT_CACHE = Path('data') / 'realdata-cache'
FRAME_ID = 'camera_depth_optical_frame'
START_NS = 1_700_000_000_000_000_000
PERIOD_NS = 33_333_333
COLOR_OFFSET_NS = 2_000_000  # colour stamped a little after depth, as on real drivers


@dataclass(frozen=True)
class Source:
    """One data source: its frame files in the cache (in bag order), reader, attributes.

    ``labels_dir`` holds ``labels.yaml`` (our committed labels: ``data/<name>`` unless given).
    """

    name: str
    files: tuple[str, ...]
    read: Callable[[Path], RealFrame]
    attributes: dict[str, Any] = field(default_factory=dict)
    labels_dir: Path | None = None

    @property
    def labels_path(self) -> Path:
        """The hand labels of this source."""
        return (self.labels_dir or DATA_DIR / self.name) / 'labels.yaml'

    def paths(self, cache: str | Path = DEFAULT_CACHE) -> list[Path]:
        """The frame files in ``cache/<name>``; a missing one is a :class:`SourceError` that
        names the fetch command."""
        folder = Path(cache) / self.name
        missing = [f for f in self.files if not (folder / f).is_file()]
        if missing:
            option = '' if Path(cache) == DEFAULT_CACHE else f' --cache {cache}'
            msg = (f'{folder}: {len(missing)} of {len(self.files)} {self.name} frame files '
                   f'missing ({missing[0]}); run `python -m endeff_ros.realdata fetch '
                   f'{self.name}{option}` first')
            raise SourceError(msg)
        return [folder / f for f in self.files]

    def frames(self, cache: str | Path = DEFAULT_CACHE) -> list[RealFrame]:
        """All frames of the source, read from the cache."""
        return [self.read(p) for p in self.paths(cache)]


SKELTRACK_FRAMES = tuple(f'depth-data-{n}.gz' for n in (
    82823944, 1028894671, 1038901490, 1045879925, 1051883281, 1058893191, 1064898470,
    1070905432, 1078881076, 1166565565, 1234568668, 1399145206))
"""Ordered by the capture counter in the names (gzip-compressed copies, see ``fetch``)."""

SOURCES: dict[str, Source] = {
    'skeltrack': Source('skeltrack', SKELTRACK_FRAMES, read_skeltrack, {
        'source': 'skeltrack', 'sensor': 'kinect_v1', 'view': 'front', 'people': 1,
        'room': 'background removed', 'real': True}),
    'five_people': Source('five_people', ('five_people.pcd',),
                          lambda p: read_five_people(p)[0], {
        'source': 'pcl_five_people', 'sensor': 'kinect_v1', 'view': 'back', 'people': 5,
        'room': 'corridor', 'real': True}),
}


def source_labels(source: Source, frames: list[RealFrame]) -> dict[str, list[Label]]:
    """The source's labels lifted with its frames' depth (``{frame name: labels}``)."""
    picks = read_labels(source.labels_path)
    by_name = {f.name: f for f in frames}
    out: dict[str, list[Label]] = {}
    for name, labs in picks.items():
        if name not in by_name:
            msg = f'{source.labels_path}: frame {name!r} is not a frame of {source.name}'
            raise LabelError(msg)
        frame = by_name[name]
        out[name] = [make_label(name, frame.depth_mm, frame.intrinsics, p) for p in labs]
    return out


#: Per-copy sensor noise of a still bag: Gaussian depth noise as a fraction of the depth
#: (a Kinect v1 at 1-3 m reads within about 0.3 %), the fraction of readings dropped at random,
#: and the colour camera's noise (grey levels).
STILL_DEPTH_NOISE = 0.003
STILL_DROPOUTS = 0.01
STILL_COLOR_NOISE = 2.0


def _noisy(depth: npt.NDArray[np.float32], rgb: npt.NDArray[np.uint8],
           rng: np.random.Generator) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]:
    """One copy of a still frame as a sensor reads it again: depth with its per-frame noise
    and dropouts (NaN), colour with its noise. Nothing in the scene moves."""
    z = depth * (1.0 + STILL_DEPTH_NOISE * rng.standard_normal(depth.shape)).astype(np.float32)
    z[rng.random(depth.shape) < STILL_DROPOUTS] = np.nan
    c = rgb.astype(np.float32) + STILL_COLOR_NOISE * rng.standard_normal(rgb.shape)
    return z.astype(np.float32), np.clip(np.rint(c), 0, 255).astype(np.uint8)


def build_bag(source: Source, out: Path, *, cache: str | Path = DEFAULT_CACHE,
              storage: str = 'mcap', repeat: int = 1, frame: int | None = None,
              noise: bool = False, seed: int = 0) -> int:
    """Write ``source`` as one bag at ``out`` (replaced if it exists); returns frames written.

    Each frame is written ``repeat`` times in a row (consecutive stamps, the same labels), so
    that the temporal estimator can be scored on a still scene; with ``repeat`` 1 the frames
    follow each other although they were not recorded consecutively. ``frame``: only that
    frame (index in the source's order), so that a bag is one still scene from its first
    frame on. ``noise``: every copy read again with a sensor's per-frame noise and dropouts
    (:func:`_noisy`): people who stand still in front of a real sensor, never bit-identical.
    """
    from rosbags.rosbag2 import Writer

    from endeff_ros.synth.frames import SynthFrame
    from endeff_ros.synth.sequences import SequenceSpec
    from endeff_ros.synth.writer import STORAGES, frame_messages, typestore

    if repeat < 1:
        msg = f'repeat must be >= 1, got {repeat}'
        raise ValueError(msg)
    frames = source.frames(cache)
    labels = source_labels(source, frames)
    if frame is not None:
        if not 0 <= frame < len(frames):
            msg = f'{source.name} has frames 0-{len(frames) - 1}, not {frame}'
            raise ValueError(msg)
        frames = frames[frame:frame + 1]
    spec = SequenceSpec(source.name, frames=len(frames) * repeat)
    out = Path(out)
    if out.exists():
        shutil.rmtree(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    writer = Writer(out, version=9, storage_plugin=STORAGES[storage])
    attributes = dict(source.attributes, **({'repeat': repeat} if repeat > 1 else {}))
    if noise:
        attributes['motion'] = 'still'
    noise_rng = np.random.default_rng(seed)
    writer.set_custom_data(ATTRIBUTES_KEY, json.dumps(attributes))
    rng = np.random.default_rng(0)
    count = 0
    with writer:
        conns: dict[str, Any] = {}
        for frame in frames:
            depth = np.where(frame.depth_mm > 0, frame.depth_mm.astype(np.float32) /
                             np.float32(1000.0), np.float32(np.nan)).astype(np.float32)
            gt, ids = gt_arrays(labels.get(frame.name, []))
            for _ in range(repeat):
                stamp = START_NS + count * PERIOD_NS
                z, rgb = _noisy(depth, frame.rgb, noise_rng) if noise else (depth, frame.rgb)
                synth = SynthFrame(index=count, stamp_ns=stamp,
                                   color_stamp_ns=stamp + COLOR_OFFSET_NS, color=rgb,
                                   depth=z, intrinsics=frame.intrinsics, gt=gt, gt_ids=ids,
                                   gt_visible=np.ones(len(ids), bool), frame_id=FRAME_ID)
                for log, topic, typ, data in frame_messages(synth, spec, rng):
                    if topic not in conns:
                        conns[topic] = writer.add_connection(topic, typ,
                                                             typestore=typestore())
                    writer.write(conns[topic], log, data)
                count += 1
    return count


def build_still_bags(out_dir: str | Path, copies: int, *, names: list[str] | None = None,
                     cache: str | Path = DEFAULT_CACHE, storage: str = 'mcap') -> list[Path]:
    """The real frames played still: one bag per labelled frame of each source (``names``,
    default all), ``<source>_<index>``, that frame ``copies`` times with per-copy sensor
    noise (:func:`build_bag`'s ``noise``). People in view from the first frame who do not
    move: what the static background must never hide."""
    written = []
    for name in names or list(SOURCES):
        if name not in SOURCES:
            msg = f'unknown source {name!r} (have {", ".join(SOURCES)})'
            raise ValueError(msg)
        source = SOURCES[name]
        for i in range(len(source.files)):
            path = Path(out_dir) / f'{name}_{i:02d}'
            build_bag(source, path, cache=cache, storage=storage, repeat=copies, frame=i,
                      noise=True, seed=i)
            written.append(path)
    return written


def build_bags(out_dir: str | Path, *, names: list[str] | None = None,
               cache: str | Path = DEFAULT_CACHE, storage: str = 'mcap', repeat: int = 1
               ) -> list[Path]:
    """One bag per source (``names``, default all) under ``out_dir`` from the frames in
    ``cache``; returns their paths."""
    written = []
    for name in names or list(SOURCES):
        if name not in SOURCES:
            msg = f'unknown source {name!r} (have {", ".join(SOURCES)})'
            raise ValueError(msg)
        path = Path(out_dir) / name
        build_bag(SOURCES[name], path, cache=cache, storage=storage, repeat=repeat)
        written.append(path)
    return written
