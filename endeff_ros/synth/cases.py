"""The still and slow bags of the mocap and rooms suites (``motion.py`` makes their joints).

Each split gets the rows of a case table (``MOCAP_FULL``, ``MOCAP_QUICK``, ``ROOMS_FULL``,
``ROOMS_QUICK``): a case, the material it is made of and its length. Material comes from the
split's *stable* clips only (committed or procedural: never a fetched one), so these bags are
the same on every machine:

- ``stand``: the clips ranked by their best quiet standing frame (``motion.standing_score``),
  the k-th ``stand`` row taking the k-th clip (cycling); walking, running, crawling and
  rolling clips are left out (their quietest frame is mid-step or on the floor);
- ``active``: clips of gesturing families (their most active window is slowed down);
- ``walk``: the walk clips (leaving, arriving).

``idle`` rows take the split's first ReActIdle clip of the catalogue, when it is loaded (the
fetched cache): a bag that exists only with the cache, but always drawn the same.

Everything a row draws (view distance, camera, body, seed, the leaving time) comes from a
generator seeded by a hash of the clip's name and the row's label, so a bag depends on its clip
and case only. Sensors and views cycle with the row; rooms cycle too, a seated person always
gets a furnished room with a chair under them.

Names: ``<split>__<clip>__m<kk>-<view>-<sensor>-<room>-p1-<motion>-<label>`` (mocap), e.g.
``test__deepmimic-humanoid3d_backflip__m03-back-d455-wall-p1-still-breathing60s``, and
``<split>__<clip>__m<kk>-<view>-<sensor>-<room>-p1-static-<motion>-<label>`` (rooms pairs), so
that ``*-still-*`` and ``*-slow-*`` select them.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from .mocap.clip import MotionClip
from .motion import CASES, cycled, feet_together, standing_score, travel_frames
from .sensors import SENSORS
from .skeleton_body import standing_height
from .suite import (
    _PEOPLE,
    _SENSORS,
    FPS,
    FULL_MAX_S,
    QUICK_BAGS,
    QUICK_FRAMES,
    BagSpec,
    PersonSpec,
    _style,
    catalogue_index,
    draw_spec,
    resampled,
    safe_name,
    set_margins,
    window_start,
)
from .views import FARTHEST_M, View


@dataclasses.dataclass(frozen=True)
class Row:
    """One row of a case table: ``case`` (``motion.CASES``), ``material`` (``stand``,
    ``active``, ``walk``, ``idle``), ``seconds`` (still cases, ``idle``: the length;
    ``arrives``: still after arriving; ``leaves``: the range the standing time is drawn from),
    ``factor`` and ``source_frames`` (``slowed``: the segment of ``source_frames`` source
    intervals is played ``factor`` times slower)."""

    case: str
    material: str
    seconds: tuple[float, float] = (0.0, 0.0)
    factor: int = 1
    source_frames: int = 0

    @property
    def label(self) -> str:
        """The row's part of a bag name: ``frozen15s``, ``slowed-x10``, ``leaves``..."""
        if self.case == 'slowed':
            return f'slowed-x{self.factor}'
        if self.case == 'leaves':
            return 'leaves'
        return f'{self.case}{self.seconds[1]:g}s'


def _rows(*rows: tuple) -> tuple[Row, ...]:
    out = []
    for case, material, value in rows:
        if case == 'slowed':
            factor, source = value
            out.append(Row(case, material, factor=factor, source_frames=source))
        else:
            span = value if isinstance(value, tuple) else (value, value)
            out.append(Row(case, material, span))
    return tuple(out)


#: Per split; about 4,600 frames per split in the full suite (the leaving time is drawn).
MOCAP_FULL = _rows(
    ('frozen', 'stand', 3.0), ('frozen', 'stand', 12.0),
    ('breathing', 'stand', 5.0), ('breathing', 'stand', 60.0),
    ('seated', 'stand', 10.0),
    ('slowed', 'active', (10, 30)), ('slowed', 'active', (20, 30)),
    ('leaves', 'walk', (3.0, 20.0)), ('arrives', 'walk', 8.0),
    ('idle', 'idle', 8.0),
)
MOCAP_QUICK = _rows(
    ('frozen', 'stand', 3.0), ('breathing', 'stand', 3.0), ('seated', 'stand', 3.0),
    ('slowed', 'active', (10, 9)), ('slowed', 'active', (20, 9)),
    ('leaves', 'walk', 3.0), ('arrives', 'walk', 1.0),
)
ROOMS_FULL = _rows(
    ('breathing', 'stand', 5.0), ('slowed', 'active', (10, 12)),
    ('leaves', 'walk', (3.0, 5.0)), ('arrives', 'walk', 3.0),
)
ROOMS_QUICK = _rows(('breathing', 'stand', 3.0),)
#: ``leaves``: frames walked on once the person is out of view (an estimator that lets go of
#: them has this long to show it); also how far (m) beyond the image's edge at their distance
#: a walk starts or ends, so that arms and legs are out of view too.
OUT_OF_VIEW_S = 1.0
OUTSIDE_M = 0.7
_ACTIVE = ('punch', 'kick', 'dance', 'wave', 'gesture', 'reach', 'jump', 'bend')
# Families whose quietest frame is still a step (a walk's passing phase lifts a foot) or a
# body on the floor: no standing material.
_MOVING = ('walk', 'turn', 'run', 'crawl', 'roll')
_STILL_VIEWS = ('front', 'side', 'back')
_STILL_ROOMS = ('empty', 'furnished', 'wall')


def stable_hash(text: str) -> int:
    """A 32-bit hash of ``text`` that is the same in every process (``hash`` is salted)."""
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:4], 'big')


def _stable(clip: MotionClip) -> bool:
    """Committed or procedural: present on every machine."""
    from .mocap.catalogue import SOURCES

    src = SOURCES.get(clip.source)
    return src is None or src.committed


def materials(clips: Sequence[MotionClip], pos: dict[str, npt.NDArray[np.float64]],
              split: str) -> dict[str, list[MotionClip]]:
    """The split's clips for each material (module docstring)."""
    from .mocap.catalogue import CLIPS

    stable = sorted((c for c in clips if c.split == split and _stable(c)),
                    key=lambda c: c.name)
    best = {c.name: float(standing_score(pos[c.name]).min()) for c in stable}
    idle = [e.name for e in CLIPS if e.source == 'reactidle' and e.split == split][:1]
    loaded = {c.name: c for c in clips}
    upright = [c for c in stable if c.family not in _MOVING] or stable
    return {
        'stand': sorted(upright, key=lambda c: (best[c.name], c.name)),
        'active': [c for c in stable if c.family in _ACTIVE] or stable,
        'walk': [c for c in stable if c.family == 'walk'],
        'idle': [loaded[n] for n in idle if n in loaded],
    }


def case_specs(clips: Sequence[MotionClip], pos: dict[str, npt.NDArray[np.float64]],
               rows: Sequence[Row], seed: int = 0) -> list[BagSpec]:
    """The case bags of ``rows`` for each split (dev, then test) of ``clips`` (``pos``: their
    joints at 30 fps), one person each, mocap-suite names."""
    return [spec for _, _, spec in case_rows(clips, pos, rows, seed)]


def case_rows(clips: Sequence[MotionClip], pos: dict[str, npt.NDArray[np.float64]],
              rows: Sequence[Row], seed: int = 0) -> list[tuple[int, Row, BagSpec]]:
    """``(row index, row, spec)`` of ``case_specs`` (the rooms suite names its pairs from
    the first two)."""
    specs = []
    for split in ('dev', 'test'):
        pools = materials(clips, pos, split)
        used: dict[str, int] = {}
        for k, row in enumerate(rows):
            pool = pools[row.material]
            nth = used.get(row.material, 0)
            used[row.material] = nth + 1
            if not pool:
                continue
            clip = pool[nth % len(pool)]
            specs.append((k, row, draw_case(k, row, clip, pos[clip.name], seed)))
    return specs


def draw_case(k: int, row: Row, clip: MotionClip, pos: npt.NDArray[np.float64],
              seed: int = 0) -> BagSpec:
    """The bag of row ``k`` made of ``clip`` (``pos``: its joints at 30 fps)."""
    label = row.label
    rng = np.random.default_rng([seed, 13, stable_hash(f'{clip.name}|{k}|{label}')])
    shift = 3 if clip.split == 'test' else 0
    sensor = SENSORS[_SENSORS[(k + shift) % len(_SENSORS)]]
    walking = row.case in ('leaves', 'arrives')
    kind = 'across' if walking else _STILL_VIEWS[(k + shift) % len(_STILL_VIEWS)]
    seated = row.case == 'seated'
    room = 'furnished' if seated else _STILL_ROOMS[(k + shift) % len(_STILL_ROOMS)]
    far = min(FARTHEST_M - 0.5, sensor.z_max - 0.7)
    dist = float(rng.uniform(1.5, far))
    cam_h = float(rng.uniform(0.6, 2.2))
    tilt = float(rng.uniform(-6.0, 6.0))
    roll = float(rng.uniform(-15.0, 15.0)) if rng.random() < 0.3 else 0.0
    side = 1 if rng.random() < 0.5 else -1
    body = _style(rng)
    texture = int(rng.integers(1000))
    # Where the clip's joints are scaled to the body (a walk's steps scale with it).
    scale = body.height_m / standing_height(pos)
    hold = 0
    if row.case == 'slowed':
        start = window_start(pos, row.source_frames + 1, 'active')
        frames = row.source_frames * row.factor
    elif walking:
        intr = sensor.intrinsics
        away = dist * 0.5 * intr.width / intr.fx + OUTSIDE_M
        walk = cycled(pos, len(pos) + round(20 * FPS)) * scale
        if row.case == 'leaves':
            start = feet_together(walk, 0, round(1.2 * FPS))
            hold = round(float(rng.uniform(*row.seconds)) * FPS)
            frames = hold + travel_frames(walk, start, away) + round(OUT_OF_VIEW_S * FPS)
        else:
            start = 0
            reach = travel_frames(walk, 0, away)
            stop = feet_together(walk, reach, reach + round(1.2 * FPS))
            hold = stop + 1
            frames = hold + round(row.seconds[1] * FPS)
    else:
        start = 0 if row.case == 'idle' else int(np.argmin(standing_score(pos)))
        frames = round(row.seconds[1] * FPS)
    view = View(kind, round(dist, 2), round(cam_h, 2), round(tilt, 1), round(roll, 1), 0.0,
                side)
    person = PersonSpec(clip.name, int(start), body, view, texture, row.case, int(hold),
                        row.factor)
    motion = CASES[row.case]
    name = (f'{clip.split}__{safe_name(clip.name)}__m{k:02d}-{kind}-{sensor.name}-{room}-p1'
            f'-{motion}-{label}')
    attrs = {'source': clip.source, 'family': clip.family, 'split': clip.split,
             'view': kind, 'camera_height_m': round(cam_h, 2), 'distance_m': round(dist, 2),
             'sensor': sensor.name, 'room': room, 'people': 1,
             'interaction': 'sit' if seated else 'none', 'build': body.build,
             'clothing': body.clothing, 'child': body.child, 'motion': motion,
             'case': row.case}
    return BagSpec(name, (person,), int(frames), room, 'sit' if seated else 'none',
                   sensor.name, int(rng.integers(2**31)), attrs)


def suite_specs(clips: Sequence[MotionClip], *, quick: bool = False, seed: int = 0,
                max_s: float = FULL_MAX_S, catalogue: Sequence[str] | None = None,
                margins: bool = True) -> list[BagSpec]:
    """The suite's bag specs for ``clips``: quick = ``QUICK_BAGS`` bags (clips repeat if
    fewer) of ``QUICK_FRAMES`` frames; full = one bag per clip, each up to ``max_s`` s (its
    most active segment), plus one multi-person bag for each clip in the first eighth of the
    catalogue (``catalogue_index``, which numbers the full suite's bags); then, in both, the
    still and slow bags of this module (``MOCAP_QUICK``, ``MOCAP_FULL``). ``margins``: false
    renders every bag without its sensor's dead margins (same names: a twin for comparison)."""
    if not clips:
        msg = 'the mocap suite needs at least one clip'
        raise ValueError(msg)
    if not max_s > 0:
        msg = f'max_s must be positive, got {max_s}'
        raise ValueError(msg)
    order = sorted(clips, key=lambda c: c.name)
    pos = {c.name: resampled(c) for c in order}
    specs = []
    if quick:
        for i in range(max(QUICK_BAGS, len(order))):
            rng = np.random.default_rng([seed, 7, i])
            specs.append(draw_spec(i, order[i % len(order)], order, pos, QUICK_FRAMES,
                                   _PEOPLE[i % len(_PEOPLE)], rng, quick))
        specs += case_specs(order, pos, MOCAP_QUICK, seed)
        return set_margins(specs, margins)
    index = catalogue_index(order, catalogue)
    total = len(index)
    # One bag per clip (the first pass over the catalogue), then the multi-person bags of the
    # first eighth of the catalogue (the second pass: the cycles shift by one lap).
    bags = [(index[c.name], c, 1, 0) for c in order]
    bags += [(total + index[c.name], c, 2 + (total + index[c.name]) % 2, 1) for c in order
             if index[c.name] < total // 8]
    for i, clip, people, lap in sorted(bags, key=lambda b: b[0]):
        rng = np.random.default_rng([seed, 7, i])
        n = int(min(len(pos[clip.name]), max(2, round(max_s * FPS))))
        specs.append(draw_spec(i, clip, order, pos, n, people, rng, quick, lap=lap))
    specs += case_specs(order, pos, MOCAP_FULL, seed)
    return set_margins(specs, margins)
