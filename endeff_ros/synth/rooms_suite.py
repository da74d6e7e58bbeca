"""The ``rooms`` suite: pairs of bags that differ only by their furniture, and camera pans.

A static background model is judged by what the furniture costs: the same person scored with
and without it. Each *pair* renders one clip segment, body, view, sensor, people and seed twice
with ``suite.BagRenderer``: once in an empty room (floor and far wall) and once furnished with
up to 5 pieces (table, chair, shelf, floor lamp, boxes; ``room.scatter``) standing beside or
behind the people, in the camera's field of view and inside the default foreground box
(``suite.BagSpec.furnish == 'beside'``: off their paths and off the lines of sight from the
camera to them, so a piece never hides a person; when that leaves fewer than two pieces, as
near people walking across the view do, more are placed deeper in the box and closer to the
people; two people filling the whole view may leave none). The person's ground truth, the
dropped frames and the stamps are the same in both bags; the furnished one adds static clutter
only.

*Pan* pairs are longer bags with the same two rooms in which the camera turns once
(``pan.Pan``: 20-30 degrees of yaw over 0.5 s, starting 1.5 s in, still afterwards) while one
person on their feet who stays in place (a clip of ``PAN_FAMILIES`` that travels less than
``STILL_M`` in its segment, seen from the front, side or back, at least 2 m away) stays in
view; the ground truth follows the camera frame by frame.

Bag names are ``<split>__<clip>__<nnn>-<view>-<sensor>-<room>-p<people>-<camera>`` (``room``
``empty`` or ``furnished``, ``camera`` ``static`` or ``pan``; ``nnn`` numbers the pairs), so
``*-furnished-*`` or ``*-pan`` select by glob. Clips are split dev/test as in the mocap suite;
each split gets ``FULL_PAIRS`` static and ``FULL_PANS`` pan pairs (``--quick``: ``QUICK_PAIRS``
and ``QUICK_PANS`` short ones), the clips spread over the split's families.

In the full suite the static pairs are spread over the whole catalogue's clips of the split
(``mocap.catalogue``, fetched or not) and the pan pairs' clips are fixed (``PAN_CLIPS``), so a
pair's clip, number, name and attributes do not depend on which clips are loaded; a pair whose
clip is not loaded is left out (its number stays unused), and a clip outside the catalogue
has none. A machine with the committed clips only lists their pairs exactly as one with the
fetched cache does. Only the partners of a two-person pair are drawn from the clips loaded.
The quick suite spreads its pairs over the clips it is given (the committed ones).

Attributes (``endeff.attributes``): the mocap suite's (``interaction`` always ``none``), plus
``camera`` (``static``/``pan``), ``pair`` (the two bag names, empty first: a list, so that
``endeff eval`` forms no group of it) and, for pans, ``pan_s`` (start and end of the turn in s
after the first frame; also a list). ``endeff.details`` adds ``pan`` with the yaw and the
stamps of the frames at which the turn starts and ends.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from .mocap.clip import JOINT_INDEX, MotionClip
from .pan import Pan
from .suite import FPS, BagSpec, draw_spec, resampled, safe_name, set_margins, window_start

PAIR_S = 3.0  # static pairs: bag length
PAN_BAG_S = 5.0  # pan pairs: bag length, with the turn
PAN_START_S = 1.5
PAN_DURATION_S = 0.5
PAN_YAW_DEG = (20.0, 30.0)  # magnitude of the turn, drawn per bag; the sign too
FULL_PAIRS = 24  # static pairs per split
FULL_PANS = 4  # pan pairs per split
QUICK_PAIRS = 2
QUICK_PANS = 1
QUICK_PAIR_FRAMES = 24
QUICK_PAN_FRAMES = 30  # 1 s: the turn from 0.3 to 0.8 s
QUICK_PAN_START_S = 0.3
STILL_M = 1.0  # a pan's clip moves its pelvis less than this from where it starts
# Families of pan clips: people on their feet (not crawling, rolling or getting up), whose
# tracks an evaluation can follow through the turn.
PAN_FAMILIES = ('wave', 'gesture', 'reach', 'punch', 'kick', 'dance', 'bend', 'jump', 'turn',
                'walk')
PAN_MIN_DISTANCE_M = 2.0
ROOMS = ('empty', 'furnished')
# The full suite's pan clips per split: ``pan_pool`` of the split's catalogue clips (sorted by
# family and name, family ``sit`` left out; cyclic clips looped to ``cli.LOOP_S``), spread
# (``_spread``) over ``FULL_PANS``. Fixed here because whether a fetched clip stays in place
# can only be measured where the cache is; test_synth_names checks them against it.
PAN_CLIPS = {
    'dev': ('bandai/dataset-1_guide_active_001',
            'bandai/dataset-2_raise-up-left-hand_elderly_001',
            'bandai/dataset-1_byebye_giant_001',
            'bandai/dataset-2_wave-left-hand_youthful_001'),
    'test': ('bandai/dataset-1_call_normal_002',
             'bandai/dataset-2_raise-up-left-hand_youthful_002',
             'bandai/dataset-1_byebye_tired_001',
             'bandai/dataset-2_wave-left-hand_normal_001'),
}
_PEOPLE = (1, 1, 1, 1, 1, 2)  # static pairs of the full suite: every sixth has two people
_PAN_VIEWS = ('front', 'side', 'back')
_J = JOINT_INDEX
T = TypeVar('T')


def _spread(pool: Sequence[T], count: int) -> list[T]:
    """``count`` clips evenly spaced over ``pool`` (cycling when it has fewer)."""
    if count <= len(pool):
        return [pool[int((k + 0.5) * len(pool) / count)] for k in range(count)]
    return [pool[k % len(pool)] for k in range(count)]


def _reach(pos: npt.NDArray[np.float64], n: int) -> float:
    """How far (m, horizontally) the pelvis gets from its first position in the ``n``-frame
    window of ``pos`` (T, 22, 3) in which the hands, feet and head move most."""
    start = window_start(pos, n, 'active')
    pel = pos[start:start + n, _J['pelvis']][:, [0, 2]]
    return float(np.linalg.norm(pel - pel[0], axis=1).max())


def pan_pool(pool: Sequence[MotionClip], pos: dict[str, npt.NDArray[np.float64]],
             n: int) -> list[MotionClip]:
    """The clips of ``pool`` a pan pair may show (``pos``: their joints at 30 fps; ``n``:
    the bag's frames): those of ``PAN_FAMILIES`` whose pelvis stays within ``STILL_M`` of
    where it starts in their most active window (all of that family if none does, all of
    ``pool`` if none is of it)."""
    upright = [c for c in pool if c.family in PAN_FAMILIES] or list(pool)
    return [c for c in upright if _reach(pos[c.name], n) < STILL_M] or upright


def _full_clips(split: str) -> tuple[list[str], list[str]]:
    """The names of the clips of ``split``'s static and pan pairs in the full suite, from the
    catalogue alone (module docstring)."""
    from .mocap.catalogue import CLIPS

    pool = sorted((e for e in CLIPS if e.split == split and e.family != 'sit'),
                  key=lambda e: (e.family, e.name))
    return [e.name for e in _spread(pool, FULL_PAIRS)], list(PAN_CLIPS[split])


def pair_specs(base: BagSpec, index: int | str, pan: Pan | None = None,
               suffix: str = '') -> list[BagSpec]:
    """The empty and the furnished bag of ``base`` (same people, frames, sensor and seed),
    with the suite's names and attributes; ``index``: the pair's number (or tag, ``m03``);
    ``pan``: the camera's turn (``None``: static); ``suffix`` ends both names."""
    first = base.people[0]
    camera = 'static' if pan is None else 'pan'
    split = base.attributes['split']
    view = base.attributes['view']
    tag = index if isinstance(index, str) else f'{index:03d}'
    stem = f'{split}__{safe_name(first.clip)}__{tag}-{view}-{base.sensor}'
    names = [f'{stem}-{room}-p{len(base.people)}-{camera}{suffix}' for room in ROOMS]
    attrs = {**base.attributes, 'interaction': 'none', 'camera': camera, 'pair': names}
    if pan is not None:
        attrs['pan_s'] = [round(pan.start_s, 3), round(pan.end_s, 3)]
    return [dataclasses.replace(base, name=name, room=room, interaction='none',
                                furnish='beside', pan=pan, suite='rooms',
                                attributes={**attrs, 'room': room})
            for name, room in zip(names, ROOMS)]


def _pan_spec(index: int, k: int, clip: MotionClip, order: list[MotionClip], pos: dict,
              n_pan: int, start_s: float, rng: np.random.Generator, quick: bool,
              lap: int | None) -> tuple[BagSpec, Pan]:
    """The base spec and the camera's turn of pan pair ``index``, the ``k``-th of its
    split."""
    base = draw_spec(index, clip, order, pos, n_pan, 1, rng, quick, lap=lap)
    yaw = float(rng.uniform(*PAN_YAW_DEG)) * (1 if rng.random() < 0.5 else -1)
    pan = Pan(start_s, PAN_DURATION_S, round(yaw, 1))
    person = base.people[0]
    view = dataclasses.replace(
        person.view, kind=_PAN_VIEWS[k % len(_PAN_VIEWS)], offset_x_m=0.0,
        distance_m=max(person.view.distance_m, PAN_MIN_DISTANCE_M))
    person = dataclasses.replace(person, view=view,
                                 start=window_start(pos[clip.name], n_pan, 'active'))
    attrs = {**base.attributes, 'view': view.kind, 'distance_m': view.distance_m}
    return dataclasses.replace(base, people=(person,), frames=n_pan, attributes=attrs), pan


def rooms_specs(clips: Sequence[MotionClip], *, quick: bool = False, seed: int = 0,
                margins: bool = True) -> list[BagSpec]:
    """The suite's bag specs for ``clips``, pair by pair (empty, then furnished), per split
    (dev, then test) the static pairs and then the pan pairs, then the still and slow pairs
    of ``cases.py`` (``ROOMS_QUICK``, ``ROOMS_FULL``; names tagged ``m<kk>``, ending in
    ``-<motion>-<case>``). Clips of family ``sit`` are left
    out: without their chair they would sit on air in the empty room. ``margins``: false
    renders the bags without the sensors' dead margins (same names). The full suite takes
    its pairs' clips from the catalogue (module docstring): only the pairs of the clips in
    ``clips`` are made, numbered as with every clip."""
    if not clips:
        msg = 'the rooms suite needs at least one clip'
        raise ValueError(msg)
    order = sorted(clips, key=lambda c: c.name)
    usable = [c for c in order if c.family != 'sit']
    if not usable:
        msg = 'the rooms suite needs a clip of a family other than sit'
        raise ValueError(msg)
    from .cases import ROOMS_FULL, ROOMS_QUICK, case_rows

    pos = {c.name: resampled(c) for c in order}
    n_pair = QUICK_PAIR_FRAMES if quick else round(PAIR_S * FPS)
    n_pan = QUICK_PAN_FRAMES if quick else round(PAN_BAG_S * FPS)
    start_s = QUICK_PAN_START_S if quick else PAN_START_S
    loaded = {c.name: c for c in order}
    specs: list[BagSpec] = []
    index = 0
    for split in ('dev', 'test'):
        if quick:
            pool = sorted((c for c in usable if c.split == split),
                          key=lambda c: (c.family, c.name))
            if not pool:
                continue
            statics: list[MotionClip | None] = list(_spread(pool, QUICK_PAIRS))
            pans: list[MotionClip | None] = list(_spread(pan_pool(pool, pos, n_pan),
                                                        QUICK_PANS))
            lap = None
        else:
            static_names, pan_names = _full_clips(split)
            statics = [loaded.get(n) for n in static_names]
            pans = [loaded.get(n) for n in pan_names]
            lap = 0  # the cycles start with the pairs, whatever the number of clips loaded
        for k, clip in enumerate(statics):
            if clip is not None:
                people = 1 if quick else _PEOPLE[k % len(_PEOPLE)]
                rng = np.random.default_rng([seed, 11, index])
                base = draw_spec(index, clip, order, pos, n_pair, people, rng, quick, lap=lap)
                specs += pair_specs(base, index)
            index += 1
        for k, clip in enumerate(pans):
            if clip is not None:
                rng = np.random.default_rng([seed, 11, index])
                base, pan = _pan_spec(index, k, clip, order, pos, n_pan, start_s, rng, quick,
                                      lap)
                specs += pair_specs(base, index, pan)
            index += 1
    for k, row, base in case_rows(usable, pos, ROOMS_QUICK if quick else ROOMS_FULL, seed):
        suffix = f'-{base.attributes["motion"]}-{row.label}'
        specs += pair_specs(base, f'm{k:02d}', suffix=suffix)
    if not specs:
        msg = 'the full rooms suite needs a clip of the catalogue (mocap/catalogue.py)'
        raise ValueError(msg)
    return set_margins(specs, margins)
