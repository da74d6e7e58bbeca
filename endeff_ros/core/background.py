"""The static background: a per-pixel background depth learned while the estimator runs.

Furniture, walls and shelves inside the foreground box are foreground to Section 3, and the
bands and the graph then give them end-effectors (a chair's legs, a shelf's corners). A
background model removes what never moved, with the person present from the first frame:

- **Background depth: the farthest depth seen** at each pixel of the (strided) depth image.
  Whatever stood in front of the background and moved away taught the model what is behind
  it, so no empty-room phase is needed. A farther reading is adopted only after
  ``FAR_FRAMES`` consecutive frames agree on it (within the margin): flying pixels at a
  depth edge jump to the far surface now and then, and a single such reading would otherwise
  make the near object's rim "changed" for ever. Readings within the margin pull the
  background towards them slowly (``FOLLOW``), so sensor noise does not ratchet it outwards
  as a pure maximum would.
- **Changed pixels**: nearer than the background by more than ``background_margin`` plus a
  term growing with z^2 (stereo and structured-light depth noise grows with z^2), then a
  3x3 opening, which removes the 1-pixel lines that flying pixels leave along static edges.
- **Foreground: the whole connected part that changed.** Pixels inside the box and off the
  floor are labelled into connected components (4-connected, cut where neighbouring depths
  jump by more than ``(EDGE_STEP + EDGE_STEP_Z z) * stride``: see :mod:`.depth_edges`,
  and, while colour comes, at the flying pixels a sensor reads between two surfaces:
  :func:`.depth_edges.flying_pixels`).
  A component is foreground when enough of its pixels changed (``MIN_CHANGED_FRACTION`` of
  it, at least ``MIN_CHANGED_PX`` full-resolution pixels), or while most of it was part of
  such a component within ``HOLD_S`` at the same depth (a person whose motion pauses for a
  few frames; not the wall an arm swept over). So a chair that was always there (no changed
  pixel) is dropped, a person whose torso stood still while an arm moved stays whole, and a
  robot's static pedestal stays with its moving arm. Pixels within ``floor.FLOOR_BAND`` of
  the floor do not connect components (the floor's noisy remnants joined feet to chair
  legs); they are kept next to kept pixels at their depth.
  Pixels without a reading inside a surface (stereo and ToF dropouts: a D455's legs at 3 m
  lose every few pixels) connect their neighbours when those agree within ``BRIDGE_STEP``
  (:func:`.depth_edges.bridge_dropouts`), and count for nothing else: otherwise a still leg
  falls apart into specks without a changed pixel, which are dropped and certified static.
  Pixels removed at depth edges (the far side of a jump) are kept only if they changed
  themselves. The edge step is large enough (about 0.37 m at 3 m with the default stride 2)
  that a body's own occlusions, hands in front of the chest or a torso bending towards the
  camera, do not cut it into a moving and a static part: with a 2 cm + 1 cm/m step the paper
  suite lost 0.027 temporal recall (clapping 0.970 -> 0.819), with this one 0.002.
  On the furnished rooms bags no component of furniture or wall had a single changed pixel
  left after the opening, while a person who barely moves (a small wave, ToF sensor) had
  0.1-0.3 % of theirs: hence the low fraction.
- **Colour motion**: a person who barely moves (idle sway, a still person seen from the back
  whose hands move in front of them) changes the depth by less than the margin for seconds,
  and would be dropped with the furniture when learning ends (docs/design.md has the
  measurements). The registered colour image sees them: the grey level of the strided image
  against the one ``COLOR_LAG_S`` before changes on the texture and outline of whatever
  moved by a pixel or two, while on static furniture it only shows sensor noise. Pixels that
  changed by more than ``COLOR_NOISE_K`` robust deviations of the image's difference (and
  ``COLOR_MIN_STEP`` grey levels), and whose depth did not turn farther since (where an arm
  was, the lamp now seen behind it is not what moved), are *stirred*; a component with
  ``COLOR_MIN_FRACTION`` of its pixels stirred moves, ten times the depth's fraction, since
  what colour sees and depth does not (a shadow, a screen) is spread thin over a surface.
  Such a component is held (``HOLD_S``) only where the same surface stirred before within
  ``COLOR_CONFIRM_S``: the outline of a runner who has just uncovered a lamp stirs a dozen
  of its pixels in one frame (colour and depth edges differ by a pixel), and a hold would
  keep the lamp for half a second. Certified-static pixels (below) within
  ``COLOR_RELEASE_PX`` of a stirred pixel are released: a person certified while standing
  still moves again. A released pixel at its certified depth only restarts its clock, and
  is static again after ``STATIC_S`` without stirring near it: a walker who passed behind a
  chair released its pixels along their outline, and standing beside it they keep it one
  component with them, so the chair would otherwise never certify again. No colour
  evidence in a frame when a third of the image changed by ``COLOR_MIN_STEP`` or more than
  ``COLOR_OUTSIDE_FRACTION`` of what holds no entity (floor, walls, beyond the box) did: the
  light changed, or the camera moved (while a pan settles, every texture edge stirs).
  Neither counts the pixels whose depth turned farther: what left them (a person walking
  away, uncovering the wall) changed their colour, not the light. Without colour (none in
  the stream, or this frame's was lost) depth alone decides. What stays static in depth but
  changes in colour (a screen showing a film, a shadow cast on a table) is kept like a
  mover. After learning the evidence is one frame late (:meth:`BackgroundModel.observe_color`
  learns a frame's colour after its depth): the node runs Sections 3-4 before the colour
  image arrives, and must see what ``endeff process`` sees. So it holds only where the
  surface of that frame is still seen: not where the depth turned farther since, nor where
  there was no reading then and the background is seen now (a runner's colour, one frame
  later, would otherwise fall on the shelf they passed and move it).
- **Certified static**: pixels dropped for ``STATIC_S`` at a steady depth stay dropped when
  a moving component joins them (the large edge step joins a person to the furniture beside
  them), until something changes in front of them or they turn farther. When learning ends,
  what the colour saw still in ``STILL_LEARNING_FRAMES`` learning frames at one depth is
  certified at once: a still person's arm that joins a shelf in the first frame after
  learning would otherwise carry the shelf along before it could certify.
- **Learning**: for ``background_learn_s`` after the start (and after a re-learn) no depth
  change can show yet. With colour evidence only the components that stir are kept, and
  the evidence is the frame's own colour (:meth:`BackgroundModel.foreground`'s ``color``;
  the node waits for it then, :attr:`BackgroundModel.wants_color`): from the second frame
  on, the first has nothing to compare with. Late evidence would leave the second frame
  without any, and the furniture in it (docs/results.md: furnished rooms' excess FPR
  +0.038 -> +0.026 on dev). Without colour everything is kept. Every frame that keeps
  everything keeps the furniture's false positives (1 s of 3 s bags kept furnished rooms at
  FPR 0.25-0.29 against 0.01-0.17 empty), but dropping at once drops a person present from
  frame 0 until they have moved by more than the margin; a moving person's changed pixels
  survive the opening within a few frames, so the default is short (0.2 s). Bookkeeping
  that would certify pixels as static also waits for its end (a person's torso would be
  certified before their arm first moved), except for what the colour saw still (above).
- **Absorption**: a pixel that stays nearer than the background, at a steady depth, for
  ``background_absorb_s`` becomes background (an object put down and left). Pixels of a
  component holding a track (:meth:`BackgroundModel.protect`, called by the tracker) restart
  that clock every frame, so a person who stands still while tracked is never absorbed.
- **Camera motion**: when a fraction ``background_camera_motion_fraction`` of the known
  pixels is nearer and another such fraction was farther within ``RECENT_FAR_S`` (the
  adopted and the pending farther readings), the whole static scene moved through the image:
  the background is re-learnt from the current frame. A person moving in front of a learnt
  background changes pixels mostly in one direction (nearer where they are; farther only
  where they stood at the start and for a few frames), a pan changes both at every depth
  edge. A person close to the camera who walks away changes as many pixels both ways, so
  with colour in the stream the depth is asked only when the colour said the whole scene
  changed (below): floor and walls that stood still in the colour image say the camera did
  not move, and a frame without that word (its colour image lost, or a person close to the
  camera stirring most of the image) waits for the next colour image. Without colour (none
  within ``COLOR_LAG_S``) the depth decides alone. Tracks are not touched (the
  tracker keeps its ids). While the camera brakes, a third
  of that fraction re-learns again during the learning time that follows (the turn's last
  degree would otherwise leave every edge of the furniture "changed"). The tracks that sat
  on a moving component for ``CARRY_AFTER_S`` when the turn began keep their components
  foreground through it, in the frames they are detected in
  (:meth:`BackgroundModel.protect`): a person standing still while the camera turns has no
  changed pixel when learning ends, and a predicted track's anchor may lie on the wall
  behind the hand it lost. The colour helps twice. When its last evidence said the whole
  scene changed (floor and walls stirred: a pan, or the light), a third of the fraction is
  enough: a turn over a floor and far walls changes few depths (turning about the vertical
  axis keeps a level floor's depth along each image row), and a change of light moves no
  depth at all. And while learning after a turn, a frame whose
  colour still says the scene moves re-learns again, so the background is the view after
  the camera stopped, not one taken mid-turn, whose furniture edges would stay "changed".
  A tilt, or the camera raised or lowered, changes depths mostly one way and passes this
  test; the floor plane moving (``floor.moved_floor``) tells it instead, through
  :meth:`BackgroundModel.camera_moved`.
  That colour is compared with the frame that re-learnt last (its grey image is kept when
  the older ones are dropped): a braking camera's last step, too small for the depth, is
  seen only so.

Everything is vectorised on the strided image the cloud is built from (320x240 by default):
a few dozen array operations and one ``cv2.connectedComponents``. Time comes from the frame
stamps; a stamp going back (a bag loop) does not move the model's clock back.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import cv2
import numpy as np

from . import kernels
from .depth_edges import (
    EDGE_STEP,
    EDGE_STEP_Z,
    bridged_edges,
    depth_components,
    far_side_pixels,
)
from .params import EndeffParams

if TYPE_CHECKING:
    import numpy.typing as npt

    from .types import Intrinsics

#: Consecutive frames that must agree on a farther depth before the background takes it.
FAR_FRAMES = 3
#: Frames without a reading after which a pixel forgets its background (it is beyond range).
MISS_FRAMES = 15
#: Weight of a reading within the margin in the background's running mean.
FOLLOW = 0.05
#: Depth-noise term of the margin: ``background_margin + NOISE_Z2 * z**2`` metres.
NOISE_Z2 = 0.005
#: A component is foreground when at least this fraction of its pixels changed ...
MIN_CHANGED_FRACTION = 0.001
#: ... and at least this many full-resolution pixels (divided by pixel_stride**2).
MIN_CHANGED_PX = 32
#: A component without changed pixels stays foreground while this fraction of its pixels
#: belonged to a component with changed pixels within the last HOLD_S seconds.
HOLD_FRACTION = 0.5
HOLD_S = 0.5
#: Farther readings adopted within this time count towards camera motion.
RECENT_FAR_S = 0.25
#: Camera motion is only judged when this fraction of the image has a known background.
MIN_KNOWN_FRACTION = 0.1
#: :meth:`BackgroundModel.changed_fraction` answers only over at least this many pixels.
MIN_CHANGED_PIXELS = 50
#: While learning after a camera motion, a motion this many times smaller re-learns again:
#: the camera is still settling (a pan brakes), and a background taken mid-turn would leave
#: the furniture's edges "changed" for good.
SETTLING_DIVISOR = 3.0
#: Pixels dropped (static) this long at the same depth stay dropped when a moving component
#: joins them.
STATIC_S = 0.25
#: A camera motion carries the tracks that sat on a moving component for at least this long.
CARRY_AFTER_S = 0.3
#: Window (pixels of the strided image, each side) in which a track finds its component.
PROTECT_RADIUS_PX = 2
#: Colour motion: the grey image is compared with the one this long before (s) ...
COLOR_LAG_S = 0.2
#: ... and a pixel stirred when its grey level changed by more than this many robust noise
#: deviations of the whole image's difference, and by at least COLOR_MIN_STEP levels.
COLOR_NOISE_K = 6.0
COLOR_MIN_STEP = 10
#: A component moves by colour alone when this fraction of its pixels (and MIN_CHANGED_PX)
#: stirred: ten times the depth's fraction, for what colour sees and depth does not (a
#: shadow, a screen) is spread thin over a surface.
COLOR_MIN_FRACTION = 0.01
#: More than this fraction of the image stirred: the light or the exposure changed, or the
#: camera moved; colour says nothing about what moved in that frame.
COLOR_GLOBAL_FRACTION = 0.3
#: More than this fraction of the pixels that hold no entity (floor, walls, beyond the box)
#: stirred: the same, for a change too small for the whole image to show it.
COLOR_OUTSIDE_FRACTION = 0.01
#: Certified-static pixels within this many pixels (strided image) of a stirred one are
#: released (their certification restarts).
COLOR_RELEASE_PX = 4
#: A component that moves by colour alone renews the hold (HOLD_S) only where the same
#: surface (depth within the margin) also moved by colour within this time before: one
#: frame's stirring (a runner's outline left on the lamp they uncovered) is no motion to hold.
COLOR_CONFIRM_S = 0.2
#: When learning ends, pixels that learning frames with colour evidence left out (nothing
#: stirred on their component) at least this many times at the same depth are certified
#: static at once: furniture a still person's arm joins in the first frame after learning.
STILL_LEARNING_FRAMES = 2
#: A component stays foreground as an entity of the start (``background_keep_initial``) while
#: at least this fraction of its pixels (and MIN_CHANGED_PX) lie where such an entity was
#: marked, at the depth it had: a still person joined by a shelf beside them is still kept,
#: a wall that a marked hand once touched is not.
INITIAL_FRACTION = 0.05
#: A person's flag (:meth:`BackgroundModel.mark`'s ``person_points``) covers the pixels their
#: entity's points project on, grown by this many strided pixels.
PERSON_GROW_PX = 2
#: A marked entity stays after ``background_person_s`` when its end-effectors were taken for
#: a person's in at least this share of the frames an end-effector lay on it until then. A
#: still entity shows the same shape in every frame, so a verdict it gets in a few of them is
#: the kinds' noise: of the furniture of the start that one vote kept on the dev split's
#: furnished subset, 3 of 10 were taken in 20-38 % of the frames, every person of the start
#: in all of them.
PERSON_SHARE = 0.5
#: A component holding at least this many points of an entity whose ends are flagged as a
#: person's is marked and voted for with the components holding those ends: a still person's
#: side or arm that the depth edges split off from them is theirs (the entity joins what lies
#: close in 3D), and would otherwise be learnt as furniture at the release. A few points, not
#: one: a flying point on a wall is no part (measured: design.md, "Parts and outline of a
#: person of the start").
MIN_PART_POINTS = 5
#: After the release, the entities of the start that stay are judged again every
#: ``background_person_s``: a kept one whose end-effectors were taken for a person's in
#: fewer than this share of the frames an end-effector lay on it (at least
#: REJUDGE_MIN_FRAMES of them) is learnt as background then. The furniture a walker passing
#: it in the first second shared an entity with keeps their votes at the release and their
#: marks after they left; the chair's own ends are not taken for a person's. Below
#: PERSON_SHARE: a still person is judged again for as long as they stay, and must not fail
#: once. No verdict in a window with fewer frames (a slow stream): people first. Measured:
#: design.md, "The static background", furniture of the start.
REJUDGE_SHARE = 0.2
REJUDGE_MIN_FRAMES = 10
#: A far-side pixel next to a still kept entity of the start and at most this far behind
#: it (m) stays with it (:meth:`BackgroundModel.foreground`): a real sensor's mixed readings
#: on a still person's outline, kept as the background-free candidate keeps them, not the
#: wall behind (1 m and more in the rooms people stand in; design.md, "Parts and
#: outline of a person of the start").
OUTLINE_BEHIND_M = 0.5


def _margin(depth: npt.NDArray[np.float32], base: float) -> npt.NDArray[np.float32]:
    """The background's depth margin at ``depth``: ``base`` (``background_margin``) plus the
    noise term ``NOISE_Z2 * z**2``."""
    return np.float32(base) + np.float32(NOISE_Z2) * depth * depth


class _Taken(NamedTuple):
    """What :meth:`BackgroundModel.observe_color` and the next frame need of the frame
    :meth:`BackgroundModel.foreground` took."""

    stamp_ns: int
    t: float  # model time
    depth: npt.NDArray[np.float32]  # strided, 0 where there is no reading
    base_margin: float  # background_margin then
    outside: npt.NDArray[np.bool_]  # readings that hold no entity (floor, walls, beyond)


def strided_grey(color: npt.NDArray[np.uint8], shape: tuple[int, int]) -> npt.NDArray[np.uint8]:
    """Grey levels of a colour (H, W, 3) or mono (H, W) uint8 image averaged down to ``shape``
    (the strided depth image's): the average also halves the per-pixel noise at stride 2."""
    grey = color if color.ndim == 2 else cv2.cvtColor(color, cv2.COLOR_RGB2GRAY)
    if grey.dtype != np.uint8:
        grey = np.clip(grey, 0, 255).astype(np.uint8)
    return cv2.resize(grey, (shape[1], shape[0]), interpolation=cv2.INTER_AREA)


def _enough(labels: npt.NDArray[np.int32], hits: npt.NDArray[np.bool_],
            total: npt.NDArray[np.int64], fraction: float, stride: int) -> npt.NDArray[np.bool_]:
    """Per label of ``labels``, whether enough of its pixels are ``hits``: ``fraction`` of its
    ``total`` pixels and MIN_CHANGED_PX full-resolution pixels (label 0: never)."""
    return _enough_of(np.bincount(labels[hits], minlength=len(total)), total, fraction, stride)


def _enough_of(counts: npt.NDArray[np.int64], total: npt.NDArray[np.int64], fraction: float,
               stride: int) -> npt.NDArray[np.bool_]:
    """Per label, whether its ``counts`` of hits are enough (:func:`_enough`)."""
    enough = counts >= np.maximum(MIN_CHANGED_PX / stride ** 2, fraction * total)
    enough[0] = False
    return enough


def _with_feet(out: npt.NDArray[np.bool_], depth: npt.NDArray[np.float32],
               low: npt.NDArray[np.bool_] | None, candidate: npt.NDArray[np.bool_],
               far_side: npt.NDArray[np.bool_], stride: int) -> npt.NDArray[np.bool_]:
    """``out`` and the parts of the band just above the floor (``low``, split at depth edges)
    that touch a pixel of ``out`` at their depth: feet, not the wall's foot beside a
    person's legs."""
    if low is None:
        return out
    band = low & candidate
    rows = np.flatnonzero(band.any(axis=1))
    if len(rows) == 0:
        return out
    # Only the rows holding the band (and one either side for the 3x3 neighbourhood): the
    # band lies along the floor, often a fraction of the image.
    rs = slice(max(int(rows[0]) - 1, 0), int(rows[-1]) + 2)
    o, z = out[rs], depth[rs]
    box = np.ones((3, 3), np.uint8)
    hi = cv2.dilate(np.where(o, z, 0).astype(np.float32), box)
    lo = cv2.erode(np.where(o, z, np.inf).astype(np.float32), box)
    step = np.float32(EDGE_STEP + EDGE_STEP_Z * 3.0) * stride
    low_labels, _ = depth_components(z, band[rs], stride, far_side[rs])
    touch = (low_labels > 0) & (z >= lo - step) & (z <= hi + step)
    attached = np.zeros(int(low_labels.max()) + 1, bool)
    attached[low_labels[touch]] = True
    attached[0] = False
    out = out.copy()
    out[rs] |= np.take(attached, low_labels)
    return out


def _windows(image: npt.NDArray, uv: npt.NDArray[np.int64]) -> npt.NDArray:
    """(N, (2r + 1)^2) values of ``image`` around N pixels (u, v), r = PROTECT_RADIUS_PX,
    clipped at the border."""
    h, w = image.shape
    offsets = np.arange(-PROTECT_RADIUS_PX, PROTECT_RADIUS_PX + 1)
    uu = np.clip(uv[:, 0, None, None] + offsets[None, None, :], 0, w - 1)
    vv = np.clip(uv[:, 1, None, None] + offsets[None, :, None], 0, h - 1)
    return image[vv, uu].reshape(len(uv), len(offsets) ** 2)


def _project(points: npt.NDArray[np.float64], intrinsics: Intrinsics, stride: int
             ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """Per point of ``points`` (N, 3, optical frame): the column and row (rounded, float) of
    the strided image's pixel it projects on, and whether it projects at all (in front of
    the camera, finite)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    with np.errstate(divide='ignore', invalid='ignore'):
        u = np.round((intrinsics.fx * pts[:, 0] / pts[:, 2] + intrinsics.cx) / stride)
        v = np.round((intrinsics.fy * pts[:, 1] / pts[:, 2] + intrinsics.cy) / stride)
    return u, v, (pts[:, 2] > 1e-6) & np.isfinite(u) & np.isfinite(v)


def _components_hit(labels: npt.NDArray[np.int32], n_labels: int,
                    hit: npt.NDArray[np.int32], min_hits: int = 1) -> npt.NDArray[np.bool_]:
    """Per pixel, whether its component (``labels``, ``n_labels`` of them) is one of ``hit``
    (0: none), at least ``min_hits`` times: a lookup table per label, faster than np.isin
    over the whole image."""
    return np.take(_labels_hit(n_labels, hit, min_hits), labels)


def _labels_hit(n_labels: int, hit: npt.NDArray[np.int32],
                min_hits: int = 1) -> npt.NDArray[np.bool_]:
    """Per label (``n_labels``), whether it is one of ``hit`` (0: none) ``min_hits`` times."""
    return np.bincount(hit[hit > 0], minlength=n_labels)[:n_labels] >= min_hits


class BackgroundModel:
    """Per-pixel background depth of one camera view, learned online (module docstring).

    :meth:`foreground` takes each frame's strided depth image and the pixels Section 3 would
    keep and returns those that are not static background; :meth:`protect` marks the
    components holding tracks; :meth:`reset` re-learns from the next frame.
    """

    def __init__(self) -> None:
        self.relearns = 0  # camera motions detected
        self.resets = 0  # re-learns asked for (reset())
        self._reset_requested = False
        self._empty_requested = False
        self._moved_requested = False
        self._clear()

    def _clear(self) -> None:
        self._bg: npt.NDArray[np.float32] | None = None
        self._fg_ids: dict[int, float] = {}  # tracks that sat on a moving component: since
        self._carried: set[int] = set()  # those of them alive when the camera moved
        self._carried_uv = np.zeros((0, 2), np.int64)  # their pixels in the last frame
        self._labels: npt.NDArray[np.int32] | None = None
        self._learn_until = 0.0
        self._release_at: float | None = None
        # (time, strided grey, strided depth) of the recent frames
        self._greys: list[tuple[float, npt.NDArray[np.uint8], npt.NDArray[np.float32]]] = []
        self._last: _Taken | None = None  # the last frame foreground() took
        self._scene_moved = False  # the last colour evidence said: the whole scene changed
        self._evidence: npt.NDArray[np.bool_] | None = None  # stirred pixels, for the next
        self._last_raw: float | None = None
        self._seen_color: int | None = None  # stamp of the last colour taken
        self._offset = 0.0
        self._t = 0.0

    def reset(self, *, empty: bool = False) -> None:
        """Re-learn from the next frame (the ``reset_background`` service). ``empty``: the
        room is empty of people now (the ``learn_empty_background`` service), so what is in
        view while learning is all background, entities with end-effectors included (not
        kept as entities of the start, ``background_keep_initial``). Only sets flags, so it
        may be called from another thread than :meth:`foreground`'s."""
        self._empty_requested = empty
        self._reset_requested = True

    def camera_moved(self) -> None:
        """The camera moved by another sign than this model's (the floor plane turned: a
        tilt, which changes depths mostly one way): the next :meth:`foreground` re-learns as
        for a camera motion it saw itself (counted in ``relearns``, tracks carried)."""
        self._moved_requested = True

    @property
    def learning(self) -> bool:
        """True while everything is still kept (the first ``background_learn_s``)."""
        return self._bg is None or self._t < self._learn_until

    @property
    def wants_color(self) -> bool:
        """True when the next frame's :meth:`foreground` should be given its colour image:
        while learning (or with a re-learn asked for), the frame's own colour decides."""
        return self._reset_requested or self.learning

    @property
    def background(self) -> npt.NDArray[np.float32] | None:
        """(H, W) background depth of the strided image, metres (0: not known), or None."""
        return self._bg

    def changed_fraction(self, depth: npt.NDArray[np.floating], mask: npt.NDArray[np.bool_],
                         params: EndeffParams) -> float | None:
        """Of the pixels ``mask`` of the strided ``depth`` image whose background is known, the
        fraction whose depth differs from it by more than the margin; None with fewer than
        ``MIN_CHANGED_PIXELS`` of them (or nothing learnt). Read-only: the frame is not
        learnt from."""
        if self._bg is None or self._bg.shape != depth.shape:
            return None
        bg = self._bg[mask]
        d = np.asarray(depth, dtype=np.float32)[mask][bg > 0]
        bg = bg[bg > 0]
        if len(bg) < MIN_CHANGED_PIXELS:
            return None
        return float(np.count_nonzero(np.abs(d - bg) > _margin(bg, params.background_margin))
                     / len(bg))

    def _clock(self, stamp_ns: int) -> float:
        """Model time (s): the stamp, never going back (a bag loop continues the clock)."""
        raw = stamp_ns * 1e-9
        if self._last_raw is not None and raw < self._last_raw:
            self._offset += self._last_raw - raw
        self._last_raw = raw
        self._t = max(self._t, raw + self._offset)
        return self._t

    def _learn(self, depth: npt.NDArray[np.float32], valid: npt.NDArray[np.bool_],
               t: float, params: EndeffParams, *, initial: bool = False) -> None:
        """Start learning from ``depth``: the background is the current frame. ``initial``:
        a learning after the start or a reset (not a camera motion, not an empty room), whose
        entities holding end-effectors are marked and kept (``background_keep_initial``)."""
        shape = depth.shape
        self._bg = np.where(valid, depth, 0).astype(np.float32)
        self._far_ref = np.zeros(shape, np.float32)
        self._far_n = np.zeros(shape, np.int16)
        self._miss_n = np.zeros(shape, np.int16)
        self._far_t = np.full(shape, -np.inf, np.float64)
        self._near_ref = np.zeros(shape, np.float32)
        self._near_since = np.full(shape, t, np.float64)
        self._kept_t = np.full(shape, -np.inf, np.float64)
        self._kept_z = np.zeros(shape, np.float32)
        self._colour_t = np.full(shape, -np.inf, np.float64)
        self._colour_z = np.zeros(shape, np.float32)
        self._static_z = np.zeros(shape, np.float32)
        self._static_since = np.zeros(shape, np.float64)
        self._still_n = np.zeros(shape, np.int16)  # learning frames left out, same depth
        self._still_z = np.zeros(shape, np.float32)
        self._seeded = False  # certified from the learning frames
        self._moving_labels = np.zeros(1, bool)
        self._out = np.zeros(shape, bool)
        # Entities of the start: their pixels' depth when marked (0: not marked).
        self._init_z = np.zeros(shape, np.float32)
        self._marking = initial and params.background_keep_initial
        # ... the frames in which an end-effector lay on them (:meth:`protect`'s tracks), and
        # those in which one was taken for a person's (``person``); those taken in fewer than
        # PERSON_SHARE of their frames are forgotten at _release_at (None: never,
        # ``background_keep_furniture``).
        self._init_seen = np.zeros(shape, np.uint16)
        self._init_votes = np.zeros(shape, np.uint16)
        self._release_at = (None if params.background_keep_furniture or not self._marking
                            else t + params.background_learn_s + params.background_person_s)
        self._person_s = params.background_person_s  # the window of each judgement
        self._rejudging = False  # the first release has passed (REJUDGE_SHARE)
        self._learn_until = t + params.background_learn_s
        self._settling = False
        # The grey images of earlier views say nothing of this one, but this frame's own (taken
        # when a camera motion re-learns) is the next frame's reference: a pan's last, small
        # step would otherwise never be seen by the colour, and the background would keep the
        # view one step before the camera stopped (every furniture edge "changed").
        self._greys = [g for g in self._greys if g[0] >= t]
        self._evidence = None

    def _remember(self, stamp_ns: int, depth: npt.NDArray[np.float32],
                  valid: npt.NDArray[np.bool_], candidate: npt.NDArray[np.bool_],
                  params: EndeffParams) -> None:
        """Keep what :meth:`observe_color` and the next frame need of the frame taken."""
        self._last = _Taken(stamp_ns, self._t, depth, params.background_margin,
                            valid & ~candidate)

    def observe_color(self, color: npt.NDArray[np.uint8] | None, stamp_ns: int) -> None:
        """Learn the colour motion of the frame :meth:`foreground` just took (the same stamp):
        ``color`` (H, W, 3) or (H, W) uint8, registered to its depth image. The pixels whose
        grey level changed since ``COLOR_LAG_S`` before (or since the oldest grey image kept,
        shortly after learning began) beyond the image's own noise, and whose depth did not
        turn farther than the margin since then (where a thing was and left, the change is
        the thing's, not that of what is seen behind it now), are the evidence the next frame
        uses. None (depth alone decides) without colour, for the first grey image, or when
        most of the image or more than ``COLOR_OUTSIDE_FRACTION`` of what holds no entity
        stirred.

        Colour comes after the depth's Sections 3-4 (the node starts those before the colour
        image arrives), hence the one frame's delay: every caller sees the same evidence.
        """
        last = self._last
        if color is None or last is None or last.stamp_ns != stamp_ns:
            self._evidence = None
            return
        if self._seen_color == stamp_ns:
            return  # foreground() took this colour with its depth
        self._evidence = self._color_evidence(color, last)

    def _color_evidence(self, color: npt.NDArray[np.uint8],
                        last: _Taken) -> npt.NDArray[np.bool_] | None:
        """The stirred pixels of ``color``, the colour of the frame ``last`` (see
        :meth:`observe_color`), or None."""
        self._seen_color = last.stamp_ns
        self._scene_moved = False
        t, depth, outside = last.t, last.depth, last.outside
        grey = strided_grey(color, depth.shape)
        greys = self._greys
        while len(greys) >= 2 and greys[1][0] <= t - COLOR_LAG_S:
            greys.pop(0)
        reference = greys[0] if greys else None
        greys.append((t, grey, depth))
        if reference is None:
            return None
        diff = cv2.absdiff(grey, reference[1])
        # The grey-level histogram (exact counts; a third of np.bincount's time on uint8).
        counts = cv2.calcHist([diff], [0], None, [256], [0, 256]).ravel().astype(np.int64)
        median = int(np.searchsorted(np.cumsum(counts), diff.size / 2))
        stirred = diff > max(COLOR_MIN_STEP, COLOR_NOISE_K * 1.4826 * median)
        # Where the depth turned farther, something left: its colour change is not the
        # surface's now seen. No reading then counts as farther than anything, as for the
        # background itself (letting such pixels stir kept more furniture: docs/results.md).
        left = depth > reference[2] + _margin(depth, last.base_margin)
        # A change of the whole image is judged on a fixed step: the noise-relative one rises
        # with it (a pan's every pixel changes, and the median with them).
        broad = (diff > COLOR_MIN_STEP) & ~left
        # What holds no entity stirred: the scene moved (or the light changed). Most of the
        # image stirring alone is no such sign: a person close to the camera fills it.
        self._scene_moved = (np.count_nonzero(broad & outside)
                             > COLOR_OUTSIDE_FRACTION * np.count_nonzero(outside))
        if self._scene_moved or np.count_nonzero(broad) > COLOR_GLOBAL_FRACTION * diff.size:
            return None  # the light changed or the camera moved: nothing to tell
        return stirred & ~left

    def foreground(self, depth: npt.NDArray[np.floating], candidate: npt.NDArray[np.bool_],
                   stamp_ns: int, params: EndeffParams, *,
                   low: npt.NDArray[np.bool_] | None = None,
                   color: npt.NDArray[np.uint8] | None = None) -> npt.NDArray[np.bool_]:
        """Learn from one frame and return the pixels of ``candidate`` that are foreground.

        ``depth`` (H, W) metres (0, NaN, inf: no reading; the caller zeroes readings beyond the
        sensor's range) is the strided image Section 3 builds the
        cloud from (``params.pixel_stride``), ``candidate`` (H, W) its pixels inside the box
        and off the floor; ``stamp_ns`` the frame's stamp; ``low`` (H, W) optional, the
        candidate pixels just above the floor, which do not connect components (the floor's
        noisy remnants would join a person's feet to a chair's legs) and are kept next to a
        kept pixel; ``color`` optional, the frame's registered colour image (as for
        :meth:`observe_color`). Returns an (H, W) mask, a subset of ``candidate``. While
        learning, the colour motion used is this frame's own (``color``; :meth:`observe_color`
        then does nothing for this stamp); after learning it is what :meth:`observe_color`
        saw in the frame before, and ``color`` is not used.
        """
        d = np.array(depth, dtype=np.float32)
        valid = (d > 0) & (d < np.inf)  # NaN compares False
        d[~valid] = 0
        t = self._clock(stamp_ns)
        stride = params.pixel_stride
        if self._reset_requested or self._bg is None or self._bg.shape != d.shape:
            self.resets += self._reset_requested
            initial = not (self._reset_requested and self._empty_requested)
            self._reset_requested = self._moved_requested = self._empty_requested = False
            self._learn(d, valid, t, params, initial=initial)
            self._remember(stamp_ns, d, valid, candidate, params)
            if color is not None:  # the first grey image (nothing to compare it with yet)
                self._evidence = self._color_evidence(color, self._last)
            self._labels, _ = depth_components(
                d, candidate, stride, far_side_pixels(d, stride, flying=color is not None))
            return candidate.copy()
        bg = self._bg
        known = valid & (bg > 0)
        margin = _margin(bg, params.background_margin)
        nearer = known & (d < bg - margin)
        farther = known & (d > bg + margin)
        stirred, self._evidence = self._evidence, None
        scene_moved, self._scene_moved = self._scene_moved, False
        # Learning: this frame's own colour decides (module docstring), and serves the next
        # frame as the evidence observe_color would have given it.
        color_now = color is not None and t < self._learn_until
        if stirred is not None and not color_now:
            # The evidence is the frame before's, and holds for the surface that was there: not
            # where the depth has turned farther since (what stirred has left: a runner passing
            # a shelf) nor where there was no reading and the background is seen now (the
            # sensor's shadow beside a moving person, whose colour stirred).
            prev = self._last.depth
            stirred = (stirred & ~((prev > 0) & (d > prev + _margin(prev, self._last.base_margin)))
                       & ~((prev <= 0) & known & ~nearer))
        self._remember(stamp_ns, d, valid, candidate, params)
        if color_now:
            stirred = self._evidence = self._color_evidence(color, self._last)
            scene_moved = self._scene_moved
        n_known = int(np.count_nonzero(known))
        # Camera motion is judged from the depth only when the colour has nothing to say: with
        # colour evidence, floor, walls and what lies beyond the box stood still in the colour
        # image (a person close to the camera walking away changes as many pixels nearer and
        # farther as a pan does). When the colour said the whole scene changed, a third of the
        # fraction will do, and while learning after a turn such a frame re-learns again
        # (module docstring, "Camera motion").
        settling = self._settling and t < self._learn_until
        # A stream with colour asks the depth only when the colour said the scene moved: a
        # frame without evidence in it (a colour image lost, most of the image stirring
        # while floor and walls stood still) waits for the next word of the colour.
        colour_live = (self._seen_color is not None
                       and stamp_ns - self._seen_color <= COLOR_LAG_S * 1e9)
        moved, self._moved_requested = self._moved_requested, False
        if (n_known >= MIN_KNOWN_FRACTION * d.size and stirred is None
                and (settling or scene_moved or not colour_live)):
            recent_far = farther | (self._far_t > t - RECENT_FAR_S)
            f = params.background_camera_motion_fraction * n_known
            if settling or scene_moved:
                f /= SETTLING_DIVISOR
            moved = moved or (settling and scene_moved) or (
                np.count_nonzero(nearer) >= f and np.count_nonzero(recent_far & known) >= f)
        if moved:
            if not settling:
                # The turn begins (tracks that became foreground as it began sit on
                # furniture): these tracks are carried through it.
                self._carried |= {i for i, since in self._fg_ids.items()
                                  if since <= t - CARRY_AFTER_S}
            self.relearns += 1
            self._learn(d, valid, t, params)
            self._settling = True
            self._labels, _ = depth_components(
                d, candidate, stride, far_side_pixels(d, stride, flying=colour_live))
            return candidate.copy()

        bg, adopt, changed = self._update_depths(d, valid, known, nearer, farther, margin, t,
                                                 params)
        self._bg = bg

        upper = candidate if low is None else candidate & ~low
        # Labelled across dropouts; the bridging pixels then belong to no component.
        # Flying pixels are cut only while colour comes: a fist punched at the camera may hang
        # on its still chest by them alone, and without colour the chest has no evidence of
        # its own motion (docs/design.md, "Flying pixels cut").
        bridged, mask, far_side = bridged_edges(d, upper, stride,
                                                flying=colour_live or color is not None)
        labels, edge = depth_components(bridged, mask, stride, far_side)
        labels[~upper] = 0
        edge &= upper
        self._labels = labels
        n = int(labels.max()) + 1
        total = np.bincount(labels.ravel(), minlength=n)
        if t < self._learn_until:
            if stirred is None or self._marking:
                # Without colour, or while the entities of the start are marked (a person
                # in view who keeps still stirs nothing): everything is kept.
                return candidate.copy()
            # Learning with colour: only what stirs (a person present from the start has not
            # moved in depth yet; furniture does neither).
            out = np.take(_enough(labels, stirred, total, COLOR_MIN_FRACTION, stride),
                          labels) & candidate
            left = upper & ~out
            same = left & (self._still_n > 0) & (np.abs(d - self._still_z) <= margin)
            self._still_n = np.where(left, np.where(same, self._still_n + 1, 1),
                                     0).astype(np.int16, copy=False)
            self._still_z = np.where(left & ~same, d, self._still_z)
            return _with_feet(out, d, low, candidate, far_side, stride)
        if not self._seeded:
            # Learning has ended: what the colour saw standing still is certified now, not
            # STATIC_S after it (by then a still person's arm may have joined it).
            self._seeded = True
            seed = ((self._still_n >= STILL_LEARNING_FRAMES)
                    & (np.abs(d - self._still_z) <= margin))
            self._static_z[seed] = d[seed]
            self._static_since[seed] = t - STATIC_S
        changed = cv2.morphologyEx(changed, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)).view(bool)
        n_changed, n_stirred, n_recent = self._label_counts(labels, changed, stirred, d, margin,
                                                            t, n)
        moving = _enough_of(n_changed, total, MIN_CHANGED_FRACTION, stride)
        initial, there = self._initial_labels(d, labels, total, margin, adopt, stride, moving)
        # Components with changed pixels renew the hold (:meth:`_certify`); one that moves by
        # colour alone only on the surface that also stirred within COLOR_CONFIRM_S.
        by_colour = (None if stirred is None
                     else _enough_of(n_stirred, total, COLOR_MIN_FRACTION, stride))
        # Held: pixels kept because of changed pixels within HOLD_S, at the same depth (the
        # same surface, not the wall an arm swept over).
        held = n_recent >= HOLD_FRACTION * total
        moved = moving if by_colour is None else moving | by_colour
        # Entities of the start count as moving for the tracks on them (carried through a
        # camera motion, as a moving person's are).
        self._moving_labels = moved | initial
        keep = moved | held | initial
        keep[self._track_labels(labels, self._carried_uv)] = True
        keep[0] = False
        k = 2 * COLOR_RELEASE_PX + 1
        stirred_near = (None if stirred is None else cv2.dilate(
            stirred.view(np.uint8), np.ones((k, k), np.uint8)).view(bool))
        out = self._certify(labels, moving, by_colour, keep, candidate, d, margin, changed, edge,
                            there, stirred_near, t)
        still_initial = initial & ~moved
        if still_initial.any():
            # The far sides of a still kept entity of the start's outline within
            # OUTLINE_BEHIND_M behind it, as the candidate has them: they never change, and
            # ``edge & changed`` alone would cut a still person's outline, which the
            # background must not touch. Not a moving one's: its outline changes.
            kept_z = np.where(np.take(still_initial, labels), d, np.float32(0))
            near_z = cv2.dilate(kept_z, np.ones((3, 3), np.uint8))
            out |= edge & (near_z > 0) & (d <= near_z + OUTLINE_BEHIND_M)
        out = _with_feet(out, d, low, candidate, far_side, stride)
        if low is not None:
            out |= low & candidate & changed
        self._out = out
        return out

    def _update_depths(self, d: npt.NDArray[np.float32], valid: npt.NDArray[np.bool_],
                       known: npt.NDArray[np.bool_], nearer: npt.NDArray[np.bool_],
                       farther: npt.NDArray[np.bool_], margin: npt.NDArray[np.float32],
                       t: float, params: EndeffParams
                       ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_],
                                  npt.NDArray[np.uint8]]:
        """The background depth's update from the frame ``d`` (:meth:`foreground`): the new
        background (a new array: callers of ``background`` may hold the last one), the pixels
        whose farther reading it adopted, and the changed pixels before the opening (uint8:
        nearer and not absorbed, or read where nothing was and not adopted). One compiled
        pass when :data:`.kernels.ENABLED`, the numpy rules otherwise (the reference)."""
        if kernels.ENABLED:
            new_bg = np.empty_like(self._bg)
            changed = np.empty(d.shape, np.uint8)
            adopt = np.empty(d.shape, bool)
            kernels.update_depths(d, valid, known, nearer, farther, margin, self._bg,
                                  self._far_n, self._far_ref, self._far_t, self._miss_n,
                                  self._near_ref, self._near_since, t,
                                  params.background_absorb_s, np.float32(FOLLOW), FAR_FRAMES,
                                  MISS_FRAMES, new_bg, changed, adopt)
            return new_bg, adopt, changed
        bg = self._bg
        # Farther readings, and readings where nothing was seen yet (no reading is beyond
        # the sensor's range: the farthest of all), are adopted once FAR_FRAMES consecutive
        # frames agree; until then a reading where nothing was seen counts as changed (a
        # person in front of a hall too deep for the sensor).
        fresh = valid & ~known
        pending = farther | fresh
        agree = pending & (self._far_n > 0) & (np.abs(d - self._far_ref) <= margin)
        # The per-pixel state is updated in place, sparse masks by assignment: each np.where
        # over the image costs a pass and an allocation (~1 ms a frame for these lines).
        far_n = self._far_n  # pending: one more if it agrees, else 1; not pending: 0
        far_n += agree
        restart = pending & ~agree
        far_n[restart] = 1
        far_n *= pending
        self._far_ref[restart] = d[restart]
        adopt = far_n >= FAR_FRAMES
        # Readings within the margin: the running mean follows them (a new array: callers of
        # ``background`` may hold the last one).
        follow = d - bg
        follow *= np.float32(FOLLOW)
        follow *= known & ~nearer & ~farther
        bg = bg + follow
        bg[adopt] = d[adopt]
        self._far_t[adopt & known] = t
        far_n[adopt] = 0
        # No reading for MISS_FRAMES frames: what was there left, nothing is seen behind it
        # (not after a few frames: dark or glossy surfaces drop out now and then).
        miss_n = self._miss_n
        miss_n += 1
        miss_n *= ~valid & (bg > 0)
        bg[miss_n >= MISS_FRAMES] = 0
        # Nearer readings: absorbed after background_absorb_s at a steady depth.
        same = nearer & (np.abs(d - self._near_ref) <= margin)
        kept_since = self._near_since[same]
        self._near_since.fill(t)
        self._near_since[same] = kept_since
        moved_nearer = nearer & ~same
        self._near_ref[moved_nearer] = d[moved_nearer]
        absorb = nearer & (t - self._near_since >= params.background_absorb_s)
        bg[absorb] = d[absorb]
        return bg, adopt, ((nearer & ~absorb) | (fresh & ~adopt)).view(np.uint8)

    def _label_counts(self, labels: npt.NDArray[np.int32], changed: npt.NDArray[np.bool_],
                      stirred: npt.NDArray[np.bool_] | None, d: npt.NDArray[np.float32],
                      margin: npt.NDArray[np.float32], t: float, n: int
                      ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64] | None,
                                 npt.NDArray[np.int64]]:
        """Per label of ``labels`` (``n`` of them), its pixels that ``changed``, that
        ``stirred`` (None without colour evidence) and that were held within ``HOLD_S`` at
        their depth (:meth:`foreground`). One compiled pass when :data:`.kernels.ENABLED`."""
        if kernels.ENABLED:
            counts = np.zeros((3, n), np.int64)
            kernels.label_counts(labels, changed, changed if stirred is None else stirred,
                                 stirred is not None, d, self._kept_t, self._kept_z, margin, t,
                                 HOLD_S, counts[0], counts[1], counts[2])
            return counts[0], None if stirred is None else counts[1], counts[2]
        recent = (t - self._kept_t <= HOLD_S) & (np.abs(d - self._kept_z) <= margin)
        return (np.bincount(labels[changed], minlength=n),
                None if stirred is None else np.bincount(labels[stirred], minlength=n),
                np.bincount(labels[recent], minlength=n))

    def _certify(self, labels: npt.NDArray[np.int32], moving: npt.NDArray[np.bool_],
                 by_colour: npt.NDArray[np.bool_] | None, keep: npt.NDArray[np.bool_],
                 candidate: npt.NDArray[np.bool_], d: npt.NDArray[np.float32],
                 margin: npt.NDArray[np.float32], changed: npt.NDArray[np.bool_],
                 edge: npt.NDArray[np.bool_], there: npt.NDArray[np.bool_],
                 stirred_near: npt.NDArray[np.bool_] | None, t: float) -> npt.NDArray[np.bool_]:
        """The per-pixel rules of :meth:`foreground` after the labels' verdicts: the hold
        renewed, static surfaces certified, kept and released, and the foreground returned.
        Per label: ``moving`` (changed pixels), ``by_colour`` (stirred; None without colour
        evidence), ``keep``; per pixel: the ``there`` of the entities of the start and
        ``stirred_near``, the stirred pixels grown by ``COLOR_RELEASE_PX``. One compiled pass
        when :data:`.kernels.ENABLED`, the numpy rules otherwise (the reference)."""
        if kernels.ENABLED:
            out = np.empty(d.shape, bool)
            colour = by_colour is not None
            kernels.certify(labels, moving, by_colour if colour else moving, colour, keep,
                            candidate, d, margin, changed, edge, there,
                            stirred_near if colour else changed, self._colour_t,
                            self._colour_z, self._kept_t, self._kept_z, self._static_z,
                            self._static_since, t, COLOR_CONFIRM_S, STATIC_S, out)
            return out
        renew = np.take(moving, labels)  # moving[labels], 2-3x faster
        if by_colour is not None:
            on_colour = np.take(by_colour, labels)
            renew |= (on_colour & (t - self._colour_t <= COLOR_CONFIRM_S)
                      & (np.abs(d - self._colour_z) <= margin))
            self._colour_t[on_colour] = t
            self._colour_z[on_colour] = d[on_colour]
        # The hold is not renewed on pixels certifying as static (furniture that a noisy edge
        # joined to a person for a frame).
        margin_ok = np.abs(d - self._static_z) <= margin
        certifying = (self._static_z > 0) & margin_ok
        renew &= ~certifying
        self._kept_t[renew] = t
        self._kept_z[renew] = d[renew]
        fg = np.take(keep, labels) & candidate
        # Certified static: pixels that were dropped for STATIC_S at the same depth stay
        # dropped when a moving component joins them (furniture a person stands next to).
        start = candidate & ~fg & ~certifying
        self._static_z[start] = d[start]
        self._static_since[start] = t
        # That surface is gone: something changed in front of it, or it left (a single
        # flying pixel at an edge does neither: the opening removed it from changed).
        gone = fg & ~margin_ok & (changed | (d > self._static_z + margin))
        if stirred_near is not None:
            # ... or it stirs: a person who stood still long enough to be certified (from the
            # start, or in a pause) and moves again by less than the margin. Where it kept its
            # depth, only its clock restarts: once nothing stirs near it for STATIC_S it is
            # static again (the chair a walker brushed past, joined to them while they stand
            # beside it, would otherwise never certify again).
            near = fg & stirred_near
            self._static_since[near & margin_ok] = t
            gone |= near & ~margin_ok
        self._static_z[gone] = 0
        # An entity of the start at its marked depth is never certified static: a still
        # person's pixels drop out of the kept set now and then (noise, dropouts, a limb
        # split off for a frame), and certified they would be cut from the person for good.
        static = ((self._static_z > 0) & margin_ok & (t - self._static_since >= STATIC_S)
                  & ~there)
        return (fg & ~(static & ~changed)) | (edge & changed)

    def _initial_labels(self, d: npt.NDArray[np.float32], labels: npt.NDArray[np.int32],
                        total: npt.NDArray[np.int64], margin: npt.NDArray[np.float32],
                        adopt: npt.NDArray[np.bool_], stride: int,
                        moving: npt.NDArray[np.bool_]
                        ) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
        """Per label, whether it is an entity of the start that stays where it was
        (``INITIAL_FRACTION`` of its pixels at their marked depth), and per pixel whether it
        is marked and at that depth. A marked pixel whose farther reading the background
        adopted is forgotten: what was there has left. ``moving``: per label, whether it has
        changed pixels in this frame."""
        if self._release_at is not None and self._t >= self._release_at:
            # The entities of the start that showed no person's end by now are furniture,
            # certified static at once where nothing moves with them: joined to a still
            # person's component (a shelf beside them), they would otherwise stay with it for
            # as long as they touch. Not in a component that moves or moved within HOLD_S: a
            # robot's pedestal stays with its moving arm.
            if self._rejudging:  # no verdict without enough frames: people first
                person = ((self._init_seen < REJUDGE_MIN_FRAMES)
                          | (self._init_votes >= REJUDGE_SHARE * self._init_seen))
            else:
                person = (self._init_votes > 0) & (self._init_votes >= PERSON_SHARE
                                                   * self._init_seen)
            recent = np.bincount(labels[self._t - self._kept_t <= HOLD_S],
                                 minlength=len(moving)) > 0
            active = np.take(moving | recent[:len(moving)], labels)
            furniture = (self._init_z > 0) & ~person & ~active
            # Where this frame has no reading, at the depth it was marked at.
            self._static_z[furniture] = np.where(d > 0, d, self._init_z)[furniture]
            self._static_since[furniture] = self._t - STATIC_S
            self._init_z[~person] = 0
            self._init_seen.fill(0)
            self._init_votes.fill(0)
            self._rejudging = True
            self._release_at = (self._t + self._person_s if (self._init_z > 0).any()
                                else None)
        marked = self._init_z > 0
        if not marked.any():
            return np.zeros(len(total), bool), marked
        self._init_z[marked & adopt] = 0
        there = marked & (np.abs(d - self._init_z) <= margin)
        return _enough(labels, there, total, INITIAL_FRACTION, stride), there

    def mark(self, positions: npt.NDArray[np.float64], intrinsics: Intrinsics,
             stride: int, person: npt.ArrayLike | None = None,
             person_points: npt.NDArray[np.float64] | None = None,
             judged: npt.ArrayLike | None = None) -> None:
        """While the background learns after the start or a reset (``background_keep_initial``),
        mark the components of the last frame holding end-effectors at ``positions`` (N, 3)
        metres, optical frame: they stay foreground for as long as they stay where they are
        (:meth:`foreground`). What never moved and holds no end-effector (walls, table tops)
        is dropped when learning ends; a person present from the start, still or not, is not.
        The tracker marks through :meth:`protect`; a caller without tracks (the single-frame
        estimator) calls this with its end-effectors, and goes on calling it after the
        learning. ``person`` (aligned with ``positions``; None: all, and the marks are kept
        for good, ``background_keep_furniture``): the end-effectors that may belong to a
        person (:func:`.kinds.may_be_person`). A marked entity whose end-effectors were flagged
        in fewer than :data:`PERSON_SHARE` of the frames an end-effector lay on it, while
        learning and within ``background_person_s`` after it, is forgotten then and learnt as
        background: furniture, by the kinds of a whole second (a person's ends are often not
        yet taken for a person's in the first frames, a cabinet's now and then are). What
        stays is judged again in each following window of ``background_person_s``, and
        forgotten when its ends were taken for a person's in fewer than
        :data:`REJUDGE_SHARE` of its frames there (furniture joined to a walker's entity at
        the start, after the walker left).
        ``person_points`` (optional): the points of the flagged end-effectors' entities; only
        the pixels they cover keep their marks, on the components of the flagged ends and on
        those holding :data:`MIN_PART_POINTS` of these points (a part the depth edges split off
        a still person), so furniture that the depth labelling joins to a still person (a
        shelf they stand beside) is learnt as background with the rest,
        certified static (:meth:`foreground` keeps certified pixels out of a component that
        stays foreground). ``judged`` (aligned with ``positions``; None: all): the
        end-effectors whose frame could tell whether they are a person's; only their frames
        count towards the share (:func:`.kinds.judged_candidates`: a caller without tracks
        sees a still person with two ends in some frames, too few to tell them from a
        lamp)."""
        if self.marking:
            self._hits(positions, intrinsics, stride, person, person_points, judged)

    def _hits(self, positions: npt.NDArray[np.float64], intrinsics: Intrinsics, stride: int,
              person: npt.ArrayLike | None = None,
              person_points: npt.NDArray[np.float64] | None = None,
              judged: npt.ArrayLike | None = None
              ) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.int64], npt.NDArray[np.int32]]:
        """Where ``positions`` project on the strided image (usable ones: ``ok``, their
        pixels ``uv``) and the component each lies on (``hit``, 0: none); the components hit
        restart their absorption clock and, while marking, the components of the positions
        flagged ``person`` (aligned with ``positions``; None: all) are marked, within the
        pixels of ``person_points`` when given, in the frames the ``judged`` ones count for
        (:meth:`mark`)."""
        labels = self._labels
        u, v, ok = _project(positions, intrinsics, stride)
        uv = np.stack([u[ok], v[ok]], axis=1).astype(np.int64)
        hit = (self._track_labels(labels, uv) if labels is not None
               else np.zeros(len(uv), np.int32))
        if hit.any() and labels is not None:
            n_labels = int(labels.max()) + 1
            held = _labels_hit(n_labels, hit)
            if not (self._marking and self._confirming and self._last is not None):
                self._near_since[np.take(held, labels)] = self._t
                return ok, uv, hit
            # The components holding a flagged entity's points (MIN_PART_POINTS): its parts
            # that the depth edges split off, with or without an end of their own.
            person_uv = (None if person_points is None
                         else self._point_uv(person_points, intrinsics, stride))
            parts = (None if person_uv is None
                     else _labels_hit(n_labels, labels[person_uv], MIN_PART_POINTS))
            counted = flagged = None
            if person is not None:
                told = None if judged is None else np.asarray(judged, dtype=bool).reshape(-1)[ok]
                counted = held if told is None else _labels_hit(n_labels, hit[told])
                flags = np.asarray(person, dtype=bool).reshape(-1)[ok]
                flagged = _labels_hit(n_labels, hit[flags])
            self._confirm(labels, held, parts, counted, flagged,
                          None if parts is None else self._point_pixels(person_uv))
        return ok, uv, hit

    def _confirm(self, labels: npt.NDArray[np.int32], held: npt.NDArray[np.bool_],
                 parts: npt.NDArray[np.bool_] | None, counted: npt.NDArray[np.bool_] | None,
                 flagged: npt.NDArray[np.bool_] | None,
                 pixels: npt.NDArray[np.bool_] | None) -> None:
        """The per-pixel marks of :meth:`_hits`, from per-label verdicts: the components
        ``held`` by a track restart their absorption clock; while learning, they and the
        person's ``parts`` (None: not told) are marked at the last frame's depth; with the
        kinds told (``counted``, ``flagged``; None: not), the marked pixels of the components
        whose frame counted count one frame more (``_init_seen``), and those of the flagged
        ones (with the parts, within the person's ``pixels``) one vote more (``_init_votes``).
        One compiled pass when :data:`.kernels.ENABLED`, the numpy rules otherwise."""
        depth = self._last.depth
        if kernels.ENABLED:
            votes = counted is not None
            kernels.confirm(labels, held, held if parts is None else parts, parts is not None,
                            self.learning, held if counted is None else counted,
                            held if flagged is None else flagged, votes,
                            kernels.NO_PIXELS if pixels is None else pixels, depth, self._t,
                            self._near_since, self._init_z, self._init_seen, self._init_votes)
            return
        on = np.take(held, labels)
        self._near_since[on] = self._t
        on_parts = None if parts is None else np.take(parts, labels)
        if self.learning:
            mark = on if on_parts is None else on | on_parts
            mark = mark & (self._init_z == 0) & (depth > 0)
            self._init_z[mark] = depth[mark]
        if counted is not None and flagged is not None:
            self._init_seen[np.take(counted, labels) & (self._init_z > 0)] += 1
            voted = np.take(flagged, labels)
            if on_parts is not None:
                voted = (voted | on_parts) & pixels
            self._init_votes[voted & (self._init_z > 0)] += 1

    @property
    def _confirming(self) -> bool:
        """True while the entities of the start are marked (learning) or judged (until
        ``background_person_s`` after learning, then in each following window for as long
        as any stays)."""
        return self.learning or (self._release_at is not None and self._t < self._release_at)

    @property
    def marking(self) -> bool:
        """True while :meth:`mark` (and :meth:`protect`) mark or confirm entities of the
        start: a caller without tracks need not find its end-effectors' kinds otherwise."""
        return self._bg is not None and self._marking and self._confirming

    @property
    def wants_people(self) -> bool:
        """True while the ``person`` flags of :meth:`mark` and :meth:`protect` decide which
        entities of the start stay (``background_keep_furniture`` false, while any is judged:
        :attr:`_confirming`); otherwise they are not read, and callers pass None."""
        return self.marking and self._release_at is not None

    def _point_uv(self, points: npt.NDArray[np.float64], intrinsics: Intrinsics,
                  stride: int) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
        """The rows and columns of the strided image's pixels that ``points`` (N, 3, optical
        frame) project on, those inside the image."""
        shape = self._labels.shape
        u, v, ok = _project(points, intrinsics, stride)
        inside = ok & (u >= 0) & (u < shape[1]) & (v >= 0) & (v < shape[0])
        return v[inside].astype(np.intp), u[inside].astype(np.intp)

    def _point_pixels(self, uv: tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]
                      ) -> npt.NDArray[np.bool_]:
        """The pixels ``uv`` (rows, columns: :meth:`_point_uv`) of the strided image grown
        by :data:`PERSON_GROW_PX` (the cloud's points are voxel means, sparser than the
        pixels, and a person's outline pixels may hold no point)."""
        out = np.zeros(self._labels.shape, np.uint8)
        out[uv] = 1
        k = 2 * PERSON_GROW_PX + 1
        return cv2.dilate(out, np.ones((k, k), np.uint8)).view(bool)

    def _track_labels(self, labels: npt.NDArray[np.int32],
                      uv: npt.NDArray[np.int64]) -> npt.NDArray[np.int32]:
        """Per pixel (u, v) of the strided image, the most frequent label around it (0:
        none): the component a track's surface anchor lies on."""
        if len(uv) == 0:
            return np.zeros(0, np.int32)
        windows = _windows(labels, uv)
        return np.array([np.bincount(row[row > 0]).argmax() if (row > 0).any() else 0
                         for row in windows], dtype=np.int32)  # a loop over tracks only

    def protect(self, positions: npt.NDArray[np.float64], ids: list[int],
                intrinsics: Intrinsics, stride: int,
                detected: npt.ArrayLike | None = None,
                person: npt.ArrayLike | None = None,
                person_points: npt.NDArray[np.float64] | None = None) -> None:
        """Tell the model where the tracks are: ``positions`` (N, 3) metres, optical frame,
        the surface anchors of the tracks with ``ids`` after the last frame. Their
        components restart the absorption clock (a tracked person standing still is not
        absorbed). The tracks that sat on a component with changed pixels when the camera
        moved keep their components foreground while they live: a person who stands still
        while the camera turns is not dropped when the learning after the turn ends, while
        tracks started on furniture during that learning do not count (only a camera motion
        carries tracks: otherwise a track that once sat on a moving chair would keep it
        for good). A carried track keeps its component only in frames it was detected in
        (``detected``, aligned with ``ids``; None: all were): a predicted track's anchor is
        where its end-effector might be, and as the end leaves it (a raised hand leaving the
        image) the anchor's window falls on the wall behind, which it would keep as an entity
        for as long as the prediction lives. ``stride``: the pixel stride the last frame was
        labelled at. While learning after the start or a reset, the components of the tracks
        are marked as entities of the start, and those of the tracks flagged ``person`` (None:
        all) keep their marks, within ``person_points`` when given (:meth:`mark`)."""
        if self._labels is None or self._bg is None:
            return
        ok, uv, hit = self._hits(positions, intrinsics, stride, person, person_points)
        track_ids = np.asarray(ids, dtype=np.int64).reshape(-1)[ok]
        seen = (np.ones(len(ok), bool) if detected is None
                else np.asarray(detected, dtype=bool).reshape(-1))[ok]
        if not self.learning:
            moving = self._moving_labels
            on_moving = (hit > 0) & (hit < len(moving)) & moving[np.minimum(hit, len(moving) - 1)]
            # ... and on a pixel kept as foreground (not on certified-static furniture that a
            # moving person's component joined).
            on_moving &= _windows(self._out, uv).any(axis=1)
            for i in track_ids[on_moving].tolist():
                self._fg_ids.setdefault(i, self._t)
        alive = set(track_ids.tolist())
        self._fg_ids = {i: since for i, since in self._fg_ids.items() if i in alive}
        self._carried &= alive
        self._carried_uv = uv[np.isin(track_ids, list(self._carried)) & seen]
