"""The ``mocap`` suite: motion-capture clips rendered as benchmark bags with attributes.

``cases.suite_specs(clips, quick=...)`` turns a clip catalogue into a deterministic list of
``BagSpec`` (clip segment, body, view, room, sensor, people, seed); ``BagRenderer`` renders one
spec into ``SynthFrame``s; ``write_bag`` writes it in the benchmark-bag form with its
attributes in the rosbag2 metadata (``custom_data``, key ``attributes.ATTRIBUTES_KEY``).

Bag names are ``<split>__<clip>__<nnn>-<view>-<sensor>-<room>-p<people>`` so that a split or
a sensor can be picked by glob (``dev__*``, ``*-d435-*``).

Views, sensors, rooms and people cycle with the bag's index (periods 5, 6, 7 and 8, shifted on
each pass over the clips), so the combinations spread over clips and splits; the random parts
(height, build, clothing, distance, camera height, tilt, roll) come from a generator seeded by
the suite seed and the bag's index, so a spec never depends on which other bags are selected.

In the full suite a bag's index is its clip's position in the whole catalogue (sorted by name;
``catalogue_index``), not among the clips that happen to be loaded: a machine with the committed
clips only draws and names their bags exactly as one with the fetched cache does. Only the
partners of a multi-person bag depend on what is loaded (they are drawn from it).
"""

from __future__ import annotations

import dataclasses
import json
import re
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..attributes import ATTRIBUTES_KEY
from .body import Entity, merge
from .frames import (
    COLOR_JITTER_NS,
    PERIOD_NS,
    T0_NS,
    SynthFrame,
    drop_indices,
    sensed_visibility,
)
from .mocap.clip import JOINT_INDEX, MotionClip
from .motion import CASES, person_joints
from .pan import Pan
from .render import Background, Camera, render, static_layer
from .room import BUILDERS, ROOMS, background_entity, scatter, sight_lines
from .sensor import color_image, depth_to_mm
from .sensors import SENSORS, sensor_depth, without_margin
from .skeleton_body import BodyStyle, build_body, carry_pose, scale_to_height, standing_height
from .views import FARTHEST_M, NEAREST_M, View, aim_camera, effective_kind, place

FPS = 30.0
QUICK_FRAMES = 24
QUICK_BAGS = 48
FULL_MAX_S = 5.0  # full suite: each clip up to this long (its most active segment)
DETAILS_KEY = 'endeff.details'
INTERACTIONS = ('none', 'occluder', 'sit', 'table', 'carry')
# How a furnished room is laid out: ``scatter`` anywhere off the people's paths (the mocap
# suite), ``beside`` also off the lines of sight to them, in the camera's field of view (the
# rooms suite: furniture that never hides the person, so a room's only effect is clutter).
FURNISH = ('scatter', 'beside')
_J = JOINT_INDEX

# The cycles (see the module docstring).
_VIEWS = ('front', 'side', 'back', 'across', 'towards')
_SENSORS = ('kinect_v1', 'azure_nfov', 'd435', 'kinect_v2', 'xtion', 'd455')
_ROOMS = ('empty', 'furnished', 'wall', 'furnished', 'empty', 'wall', 'furnished')
_PEOPLE = (1, 1, 1, 2, 1, 1, 3, 1)
_SHIRTS = [(0.20, 0.35, 0.70), (0.70, 0.20, 0.20), (0.20, 0.55, 0.30), (0.60, 0.55, 0.20),
           (0.85, 0.85, 0.82), (0.12, 0.12, 0.14)]
_TROUSERS = [(0.22, 0.22, 0.30), (0.35, 0.30, 0.25), (0.15, 0.20, 0.35), (0.08, 0.08, 0.09)]
_SKINS = [(0.85, 0.65, 0.52), (0.62, 0.44, 0.32), (0.92, 0.76, 0.64), (0.42, 0.29, 0.20)]
_SHOES = [(0.30, 0.18, 0.10), (0.08, 0.08, 0.08), (0.85, 0.85, 0.85)]


@dataclass(frozen=True)
class PersonSpec:
    """One person of a bag: clip name, first frame of the segment (30 fps), body, view, and
    how the clip moves (``motion.person_joints``): ``case`` (``motion.CASES``), ``hold``
    (frames still before leaving, or walking before stopping) and ``factor`` (slow-down)."""

    clip: str
    start: int
    body: BodyStyle
    view: View
    texture: int
    case: str = 'segment'
    hold: int = 0
    factor: int = 1

    def __post_init__(self) -> None:
        if self.case not in CASES:
            msg = f'case must be one of {sorted(CASES)}, got {self.case!r}'
            raise ValueError(msg)


@dataclass(frozen=True)
class BagSpec:
    """Everything needed to render one bag. ``attributes`` lacks ``truncated``, which is
    measured while rendering (a ground-truth point projects outside the image). ``furnish``:
    one of ``FURNISH``; ``pan``: the camera's one turn (``None``: a static camera); ``suite``:
    the suite's name in the bag's details; ``margins``: the sensor's dead margins of registered
    depth (``sensors.DeadMargin``) are rendered (false: its twin without them, for
    comparison)."""

    name: str
    people: tuple[PersonSpec, ...]
    frames: int
    room: str
    interaction: str
    sensor: str
    seed: int
    attributes: dict[str, Any] = field(default_factory=dict)
    furnish: str = 'scatter'
    pan: Pan | None = None
    suite: str = 'mocap'
    margins: bool = True

    def __post_init__(self) -> None:
        problems = []
        if not self.people:
            problems.append('no people')
        if self.frames < 1:
            problems.append(f'frames must be >= 1, got {self.frames}')
        if self.room not in ROOMS:
            problems.append(f'room must be one of {ROOMS}, got {self.room!r}')
        if self.interaction not in INTERACTIONS:
            problems.append(f'interaction must be one of {INTERACTIONS}, got '
                            f'{self.interaction!r}')
        if self.sensor not in SENSORS:
            problems.append(f'sensor must be one of {sorted(SENSORS)}, got {self.sensor!r}')
        if self.furnish not in FURNISH:
            problems.append(f'furnish must be one of {FURNISH}, got {self.furnish!r}')
        if problems:
            msg = f'bag spec {self.name!r}: ' + '; '.join(problems)
            raise ValueError(msg)


def resampled(clip: MotionClip) -> npt.NDArray[np.float64]:
    """The clip's joints (T, 22, 3) at 30 fps (linear interpolation when recorded otherwise)."""
    if abs(clip.fps - FPS) < 1e-6:
        return clip.positions
    n = int(np.floor(clip.duration_s * FPS)) + 1
    x = np.arange(n) * clip.fps / FPS
    i = np.minimum(x.astype(int), len(clip.positions) - 2)
    w = (x - i)[:, None, None]
    return (1 - w) * clip.positions[i] + w * clip.positions[i + 1]


def window_start(pos: npt.NDArray[np.float64], n: int, mode: str) -> int:
    """First frame of the ``n``-frame window of ``pos`` (T, 22, 3): the one that travels
    farthest (``walk``), holds the lowest pelvis (``sit``), or moves the hands and feet most."""
    t = len(pos)
    if t <= n:
        return 0
    if mode == 'sit':
        low = int(np.argmin(pos[:, _J['pelvis'], 1]))
        return int(np.clip(low - 2 * n // 3, 0, t - n))
    if mode == 'walk':
        pel = pos[:, _J['pelvis'], [0, 2]]
        return int(np.argmax(np.linalg.norm(pel[n - 1:] - pel[:t - n + 1], axis=1)))
    ends = [_J[k] for k in ('l_wrist', 'r_wrist', 'l_ankle', 'r_ankle', 'head_top')]
    speed = np.linalg.norm(np.diff(pos[:, ends], axis=0), axis=2).sum(1)
    c = np.concatenate([[0.0], np.cumsum(speed)])
    return int(np.argmax(c[n - 1:] - c[:t - n + 1]))


def _approach_frames(seg: npt.NDArray[np.float64]) -> int:
    """Frames of the walk ``seg`` (T, 22, 3) that an approach towards the camera keeps: those
    before the pelvis has covered the activity area's depth (``FARTHEST_M - NEAREST_M``), so
    that the walk starts inside the area; at least one second."""
    pel = seg[:, _J['pelvis'], [0, 2]]
    covered = np.linalg.norm(pel - pel[0], axis=1)
    beyond = np.flatnonzero(covered > FARTHEST_M - NEAREST_M)
    n = int(beyond[0]) if len(beyond) else len(seg)
    return int(min(len(seg), max(n, round(FPS))))


def _sits(pos: npt.NDArray[np.float64], n: int) -> bool:
    """Whether the sitting window of ``pos`` (T, 22, 3) brings the pelvis down to a chair's
    height: below 42 % of the standing height (standing: about 54 %, seated on a 0.46 m chair:
    about 30 %). A clip labelled ``sit`` that climbs or perches higher gets no chair."""
    start = window_start(pos, n, 'sit')
    low = float(pos[start:start + n, _J['pelvis'], 1].min())
    return low < 0.42 * standing_height(pos)


def safe_name(name: str) -> str:
    """A clip name as a part of a bag name: any run of other characters becomes ``-``."""
    return re.sub(r'[^A-Za-z0-9_-]+', '-', name).strip('-') or 'clip'


def _style(rng: np.random.Generator) -> BodyStyle:
    child = rng.random() < 0.12
    height = float(rng.uniform(1.1, 1.3) if child else rng.uniform(1.5, 1.95))
    build = ('slim', 'average', 'average', 'heavy')[int(rng.integers(4))]
    clothing = ('plain', 'plain', 'sleeves', 'coat', 'skirt')[int(rng.integers(5))]
    pick = lambda opts: opts[int(rng.integers(len(opts)))]  # noqa: E731
    return BodyStyle(round(height, 2), build, clothing, child, pick(_SHIRTS), pick(_TROUSERS),
                     pick(_SKINS), pick(_SHOES), pick(_SHIRTS[:4]))


def _is_walk(clip: MotionClip, pos: npt.NDArray[np.float64], n: int) -> bool:
    start = window_start(pos, n, 'walk')
    seg = pos[start:start + n, _J['pelvis']]
    return float(np.linalg.norm((seg[-1] - seg[0])[[0, 2]])) >= 0.4


def catalogue_index(clips: Sequence[MotionClip],
                    catalogue: Sequence[str] | None = None) -> dict[str, int]:
    """Each clip's index in the full suite: its position among the ``catalogue``'s names
    (default: every clip of ``mocap.catalogue``, fetched or not), sorted; clips outside the
    catalogue (procedural ones) follow, sorted by name. It does not depend on which catalogue
    clips are loaded, so neither do the bags' draws and names."""
    if catalogue is None:
        from .mocap.catalogue import CLIPS

        catalogue = [e.name for e in CLIPS]
    names = sorted(set(catalogue))
    known = set(names)
    names += sorted({c.name for c in clips} - known)
    return {name: k for k, name in enumerate(names)}


def set_margins(specs: Sequence[BagSpec], margins: bool) -> list[BagSpec]:
    """``specs`` rendering (or not) their sensors' dead margins, as their attribute
    ``margins`` says."""
    return [dataclasses.replace(s, margins=margins,
                                attributes={**s.attributes, 'margins': margins})
            for s in specs]


def draw_spec(i: int, clip: MotionClip, order: list[MotionClip], pos: dict, n: int,
              people: int, rng: np.random.Generator, quick: bool,
              lap: int | None = None) -> BagSpec:
    """The spec of bag ``i`` of ``clip`` (``order``: every clip, sorted by name; ``pos``:
    their joints at 30 fps; ``n`` frames): sensor, view and room from the cycles, the rest
    drawn from ``rng``. ``lap`` shifts the cycles (default: ``i // len(order)``, one shift
    per pass over the clips). Everything but a multi-person bag's partners depends on ``i``,
    ``lap``, ``clip`` and ``rng`` only: the other clips of ``order`` supply the partners."""
    if lap is None:
        lap = i // len(order)
    sensor = SENSORS[_SENSORS[(i + lap) % len(_SENSORS)]]
    kind = _VIEWS[(i + 2 * lap) % len(_VIEWS)]
    room = _ROOMS[(i + 3 * lap) % len(_ROOMS)]
    walkers = [c for c in order if c.split == clip.split and c.name != clip.name
               and _is_walk(c, pos[c.name], n)] if people > 1 else []
    if people > 1:
        kind = 'across'
    if clip.family == 'sit' and _sits(pos[clip.name], n):
        interaction, room = 'sit', 'furnished'
    elif kind in ('across', 'towards') and room == 'furnished' and people == 1:
        interaction = 'occluder' if i % 2 else 'carry'
    elif room == 'furnished' and people == 1:
        interaction = ('table', 'occluder', 'none')[i % 3]
    else:
        interaction = 'carry' if (i % 11 == 4 and people == 1) else 'none'
    far = min(FARTHEST_M, sensor.z_max - 0.7)
    dist = float(rng.uniform(1.2, far))
    cam_h = float(rng.uniform(0.6, 2.2))
    tilt = float(rng.uniform(-6.0, 6.0))
    roll = float(rng.uniform(-15.0, 15.0)) if rng.random() < 0.3 else 0.0
    off = 0.0
    if i % 6 == 5:  # deliberately cut at the border
        off = float(rng.choice([-1.0, 1.0])) * 0.8 * dist * sensor.intrinsics.width / (
            2 * sensor.intrinsics.fx)
    side = 1 if rng.random() < 0.5 else -1
    mode = 'sit' if interaction == 'sit' else ('walk' if kind in ('across', 'towards')
                                              else 'active')
    first = PersonSpec(clip.name, window_start(pos[clip.name], n, mode), _style(rng),
                       View(kind, round(dist, 2), round(cam_h, 2), round(tilt, 1),
                            round(roll, 1), round(off, 2), side), int(rng.integers(1000)))
    if effective_kind(pos[clip.name][first.start:first.start + n], kind) == 'towards':
        n = _approach_frames(pos[clip.name][first.start:first.start + n])
    persons = [first]
    pool = walkers or [c for c in order if c.split == clip.split] or order
    for k in range(1, people):
        other = pool[int(rng.integers(len(pool)))]
        okind = effective_kind(pos[other.name][:n], 'across') if walkers else kind
        sep = 0.0 if okind == 'across' else (k - 0.5) * 0.75 * (-1) ** k
        # Behind the first person if the sensor still reaches there, else in front of it.
        odist = next((d for d in (dist + 0.85 * k, dist - 0.85 * k) if 1.2 <= d <= far),
                     float(np.clip(dist + 0.85 * k, 1.2, far)))
        persons.append(PersonSpec(
            other.name, window_start(pos[other.name], n, 'walk'), _style(rng),
            View('across', round(odist, 2), round(cam_h, 2), round(tilt, 1),
                 round(roll, 1), round(off + sep, 2), -side if k % 2 else side),
            int(rng.integers(1000))))
    view_kind = effective_kind(pos[clip.name][first.start:first.start + n], kind)
    name = (f'{clip.split}__{safe_name(clip.name)}__{i:03d}-{view_kind}-{sensor.name}'
            f'-{room}-p{people}')
    attrs = {'source': clip.source, 'family': clip.family, 'split': clip.split,
             'view': view_kind, 'camera_height_m': round(cam_h, 2),
             'distance_m': round(dist, 2), 'sensor': sensor.name, 'room': room,
             'people': people, 'interaction': interaction, 'build': first.body.build,
             'clothing': first.body.clothing, 'child': first.body.child,
             'motion': CASES['segment'], 'case': 'segment'}
    return BagSpec(name, tuple(persons), n, room, interaction, sensor.name,
                   int(rng.integers(2**31)), attrs)


class BagRenderer:
    """Renders one ``BagSpec``: ``frames()`` yields the ``SynthFrame``s in order; afterwards
    ``truncated`` says whether the ground truth of a person in view had a point outside the
    image (not listed),
    ``furniture`` holds (kind, primitives) of each piece (scene frame), ``clutter`` their
    kinds, ``camera`` is the camera used."""

    def __init__(self, spec: BagSpec, clips: dict[str, MotionClip]) -> None:
        missing = [p.clip for p in spec.people if p.clip not in clips]
        if missing:
            msg = f'bag {spec.name!r}: clips not in the catalogue: {", ".join(missing)}'
            raise KeyError(msg)
        self.spec = spec
        self.model = SENSORS[spec.sensor] if spec.margins else without_margin(
            SENSORS[spec.sensor])
        self.truncated = False
        self.joints: list[npt.NDArray[np.float64]] = []
        kinds = []
        for k, p in enumerate(spec.people):
            full = scale_to_height(resampled(clips[p.clip]), p.body.height_m)
            seg, centre = person_joints(full, p.case, p.start, spec.frames, p.hold, p.factor,
                                        np.random.default_rng([spec.seed, 5, k]))
            placed, kind = place(seg, p.view, centre)
            self.joints.append(placed)
            kinds.append(kind)
        self.view_kind = kinds[0]
        rng = np.random.default_rng([spec.seed, 1])
        self.carry: npt.NDArray[np.float64] | None = None
        if spec.interaction == 'carry':
            self.carry = np.array([rng.uniform(0.14, 0.2), rng.uniform(0.08, 0.15),
                                   rng.uniform(0.1, 0.16)])
        furniture = self._furnish(rng)
        self.furniture = furniture
        self.clutter = [k for k, _ in furniture]
        far = max(-float(j[:, _J['pelvis'], 2].min()) for j in self.joints)
        wall_z = -(far + float(rng.uniform(0.45, 0.9))) if spec.room == 'wall' else -5.5
        self.aimed = aim_camera(self.joints[0], spec.people[0].view, self.model.intrinsics,
                                wall_z)
        self.camera: Camera = self.camera_at(0)
        self._room = background_entity([p for _, ps in furniture for p in ps])
        self.static = static_layer(self._room, self.camera)
        self._static_cam = self.camera

    def camera_at(self, index: int) -> Camera:
        """The camera of frame ``index``: the one aimed at the first person, turned by the
        spec's pan (if any) at that frame's time."""
        pan = self.spec.pan
        if pan is None:
            return self.aimed
        return dataclasses.replace(self.aimed, yaw=float(pan.yaw_at(index / FPS)))

    def _static_for(self, cam: Camera) -> Background:
        """The room drawn for ``cam``, redrawn only when the camera has turned (a static
        camera pays once per bag; a pan once per frame of its turn)."""
        if cam != self._static_cam:
            self.static = static_layer(self._room, cam)
            self._static_cam = cam
        return self.static

    def _furnish(self, rng: np.random.Generator) -> list[tuple[str, list]]:
        """Furniture of the room plus the piece the interaction needs (scene frame)."""
        spec, j = self.spec, self.joints[0]
        out: list[tuple[str, list]] = []
        pel = j[:, _J['pelvis']]
        face = np.cross(j[:, _J['l_hip']] - j[:, _J['r_hip']], [0.0, 1.0, 0.0])[:, [0, 2]]
        face /= np.maximum(np.linalg.norm(face, axis=1, keepdims=True), 1e-9)
        if spec.interaction == 'sit':
            low = int(np.argmin(pel[:, 1]))
            f = face[low]
            seat = float(np.clip(pel[low, 1] - 0.1 * spec.people[0].body.height_m / 1.75,
                                 0.3, 0.6))
            x, z = pel[low, [0, 2]] - 0.04 * f
            yaw = float(np.arctan2(f[0], f[1]))
            out.append(('chair', BUILDERS['chair'](float(x), float(z), yaw, seat=seat)))
        elif spec.interaction == 'table':
            hands = j[:, [_J['l_hand_end'], _J['r_hand_end']]]
            f = face.mean(0)
            f /= max(np.linalg.norm(f), 1e-9)
            reach = ((hands[..., [0, 2]] - pel[:, None, [0, 2]]) @ f)
            t, h = np.unravel_index(int(np.argmax(reach)), reach.shape)
            top = float(np.clip(hands[t, h, 1] - 0.02, 0.6, 0.95))
            depth = 0.7
            c = pel[:, [0, 2]].mean(0) + (max(float(reach.max()), 0.25) - 0.08 + depth / 2) * f
            yaw = float(np.arctan2(f[0], f[1]))
            out.append(('table', BUILDERS['table'](float(c[0]), float(c[1]), yaw, height=top,
                                                    depth=depth)))
        elif spec.interaction == 'occluder':
            kind = ('table', 'boxes', 'chair')[int(rng.integers(3))]
            near = float(pel[:, 2].max())
            x = float(pel[:, 0].mean() + rng.uniform(-0.2, 0.2))
            z = near + float(rng.uniform(0.55, 0.8))
            if -z < 0.9:
                z = -0.9
            out.append((kind, BUILDERS[kind](x, z, float(rng.uniform(-0.3, 0.3)))))
        if spec.room == 'furnished':
            clear = np.concatenate([jj[:, _J['pelvis']][:, [0, 2]] for jj in self.joints])
            taken = [np.mean([p.center[[0, 2]] for p in ps], axis=0) for _, ps in out]
            clear = np.concatenate([clear] + [np.array([t]) for t in taken])
            dist = spec.people[0].view.distance_m
            z_range = (-min(dist + 1.5, 4.2), -0.9)
            if spec.furnish == 'beside':
                intr = self.model.intrinsics
                half_fov = float(np.arctan2(0.5 * intr.width, intr.fx)) - np.deg2rad(4.0)
                clear = np.concatenate([clear, sight_lines(clear[::3])])
                pieces = scatter(rng, clear, int(rng.integers(3, 6)), (-1.5, 1.5), z_range,
                                 half_fov=half_fov)
                if len(pieces) < 2:
                    # The people and the lines of sight to them fill the room near them (a
                    # walk across, two people): use the whole depth of the foreground box and
                    # a smaller clearance, away from every part of the pieces already placed.
                    parts = [p.center[[0, 2]] for _, ps in pieces for p in ps]
                    more = scatter(rng, np.concatenate([clear, np.reshape(parts, (-1, 2))]),
                                   6, (-1.5, 1.5), (-4.2, -0.9), clear_m=0.2, half_fov=half_fov)
                    pieces += more[:3 - len(pieces)]
                out += pieces
            else:
                out += scatter(rng, clear, int(rng.integers(2, 5)), (-1.5, 1.5), z_range)
        return out

    def entity(self, index: int) -> tuple[Entity, npt.NDArray[np.bool_]]:
        """The people of frame ``index`` (scene frame) and which ground-truth points to list:
        those of people with at least one joint inside the image."""
        people, listed = [], []
        intr = self.model.intrinsics
        for k, (p, jj) in enumerate(zip(self.spec.people, self.joints)):
            joints = jj[index]
            extra = []
            if self.carry is not None and k == 0:
                joints, carried = carry_pose(joints, self.carry)
                extra = [carried]
            e = build_body(joints, p.body, p.texture)
            e.prims.extend(extra)
            e.gt_ids = e.gt_ids + 5 * k
            people.append(e)
            cam_pts = self.camera_at(index).to_optical(joints)
            front = cam_pts[:, 2] > 0.1
            uv = intr.project(cam_pts[front]) if front.any() else np.zeros((0, 2))
            inside = ((uv[:, 0] >= 0) & (uv[:, 0] < intr.width) & (uv[:, 1] >= 0)
                      & (uv[:, 1] < intr.height)).any()
            listed.append(np.full(len(e.gt), bool(inside)))
        return merge(people), np.concatenate(listed)

    def frames(self) -> Iterator[SynthFrame]:
        spec, intr = self.spec, self.model.intrinsics
        n = spec.frames
        drop_c, drop_d = drop_indices(np.random.default_rng([spec.seed, 2]), n)
        jit = np.random.default_rng([spec.seed, 4]).integers(
            -COLOR_JITTER_NS, COLOR_JITTER_NS + 1, size=n)
        for i in range(n):
            ent, listed = self.entity(i)
            cam = self.camera_at(i)
            ren = render(ent, cam, self._static_for(cam))
            rng = np.random.default_rng([spec.seed, 3, i])
            depth = sensor_depth(ren, self.model, rng)
            color = color_image(ren, rng)
            mm = depth_to_mm(depth)
            depth = np.where(mm > 0, mm.astype(np.float32) / np.float32(1000.0),
                             np.float32(np.nan))
            vis = sensed_visibility(ren, ent.gt_prims, depth)
            # Listed: the end-effectors in the field of view (projecting inside the image),
            # hidden or not; one outside it cannot be seen by any image-based method.
            if len(ren.gt):
                uv = intr.project(ren.gt)
                out = ((ren.gt[:, 2] <= 0) | (uv[:, 0] < 0) | (uv[:, 0] > intr.width - 1)
                       | (uv[:, 1] < 0) | (uv[:, 1] > intr.height - 1))
                self.truncated |= bool((out & listed).any())
                listed = listed & ~out
            stamp = T0_NS + i * PERIOD_NS
            yield SynthFrame(i, stamp, stamp + int(jit[i]), None if i in drop_c else color,
                             None if i in drop_d else depth, intr, ren.gt[listed].copy(),
                             ent.gt_ids[listed].astype(np.uint32), vis[listed],
                             self.camera.frame_id)

    def attributes(self) -> dict[str, Any]:
        """The bag's attributes (valid after ``frames()`` ran to the end)."""
        out = dict(self.spec.attributes)
        out['view'] = self.view_kind
        # As rendered: an approaching walk may have been pushed back to stop before the camera.
        out['distance_m'] = round(-float(self.joints[0][:, _J['pelvis'], 2].mean()), 2)
        out['truncated'] = self.truncated
        out['clutter'] = list(self.clutter)
        out['margins'] = self.model.margin is not None
        return out

    def details(self) -> dict[str, Any]:
        """What is needed to reproduce the bag beyond the attributes (not grouped by eval)."""
        cam = self.camera
        out = {'suite': self.spec.suite, 'frames': self.spec.frames, 'fps': FPS,
               'pitch_deg': round(float(np.rad2deg(cam.pitch)), 2),
               'roll_deg': round(float(np.rad2deg(cam.roll)), 2),
               'wall_z_m': round(cam.wall_z, 2), 'seed': self.spec.seed,
               'people': [{'clip': p.clip, 'start_frame': p.start, 'body': p.body.label,
                           'view': asdict(p.view), 'case': p.case, 'hold_frames': p.hold,
                           'slow_factor': p.factor} for p in self.spec.people]}
        if self.spec.pan is not None:
            pan = self.spec.pan
            # Frame i is at i / FPS s for the motion and at T0_NS + i * PERIOD_NS in the bag.
            out['pan'] = {**asdict(pan), 'end_s': pan.end_s,
                          'start_stamp_ns': T0_NS + round(pan.start_s * FPS * PERIOD_NS),
                          'end_stamp_ns': T0_NS + round(pan.end_s * FPS * PERIOD_NS)}
        return out


def write_bag(spec: BagSpec, clips: dict[str, MotionClip], out: Path,
              storages: Sequence[str] = ('mcap',), compress: bool = True) -> dict[str, Any]:
    """Render ``spec`` and write ``out/<storage>/<spec.name>`` (mcap chunks zstd-compressed
    unless ``compress`` is false); returns its attributes plus ``frames`` (written)."""
    from .sequences import SequenceSpec
    from .writer import write_bags

    ren = BagRenderer(spec, clips)
    seq = SequenceSpec(spec.name, spec.frames, '16UC1', ren.model.color_encoding, 1)
    paths = {s: Path(out) / s / spec.name for s in storages}
    meta = lambda: {ATTRIBUTES_KEY: json.dumps(ren.attributes(), sort_keys=True),  # noqa: E731
                    DETAILS_KEY: json.dumps(ren.details(), sort_keys=True)}
    frames = write_bags(ren.frames(), seq, paths, spec.seed, custom_data=meta, compress=compress)
    return {**ren.attributes(), 'frames': frames}
