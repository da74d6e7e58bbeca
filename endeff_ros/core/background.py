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
  jump by more than ``(EDGE_STEP + EDGE_STEP_Z z) * stride``: see :func:`depth_components`).
  A component is foreground when enough of its pixels changed (``MIN_CHANGED_FRACTION`` of
  it, at least ``MIN_CHANGED_PX`` full-resolution pixels), or while most of it was part of
  such a component within ``HOLD_S`` at the same depth (a person whose motion pauses for a
  few frames; not the wall an arm swept over). So a chair that was always there (no changed
  pixel) is dropped, a person whose torso stood still while an arm moved stays whole, and a
  robot's static pedestal stays with its moving arm. Pixels within ``cloud.FLOOR_BAND`` of
  the floor do not connect components (the floor's noisy remnants joined feet to chair
  legs); they are kept next to kept pixels at their depth.
  Pixels removed at depth edges (the far side of a jump) are kept only if they changed
  themselves. The edge step is large enough (about 0.37 m at 3 m with the default stride 2)
  that a body's own occlusions, hands in front of the chest or a torso bending towards the
  camera, do not cut it into a moving and a static part: with a 2 cm + 1 cm/m step the paper
  suite lost 0.027 temporal recall (clapping 0.970 -> 0.819), with this one 0.002.
  On the furnished rooms bags no component of furniture or wall had a single changed pixel
  left after the opening, while a person who barely moves (a small wave, ToF sensor) had
  0.1-0.3 % of theirs: hence the low fraction.
- **Certified static**: pixels dropped for ``STATIC_S`` at a steady depth stay dropped when
  a moving component joins them (the large edge step joins a person to the furniture beside
  them), until something changes in front of them or they turn farther.
- **Learning**: for ``background_learn_s`` after the start (and after a re-learn) everything
  is kept; components then need changed pixels. Every frame of it keeps the furniture's
  false positives (1 s of 3 s bags kept furnished rooms at FPR 0.25-0.29 against 0.01-0.17
  empty), but dropping at once drops a person present from frame 0 until they have moved by
  more than the margin; a moving person's changed pixels survive the opening within a few
  frames, so the default is short (0.2 s). Bookkeeping that would certify pixels as static
  also waits for its end (a person's torso would be certified before their arm first moved).
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
  edge. Tracks are not touched (the tracker keeps its ids). While the camera brakes, a third
  of that fraction re-learns again during the learning time that follows (the turn's last
  degree would otherwise leave every edge of the furniture "changed"). The tracks that sat
  on a moving component for ``CARRY_AFTER_S`` when the turn began keep their components
  foreground through it (:meth:`BackgroundModel.protect`): a person standing still while the
  camera turns has no changed pixel when learning ends.

Everything is vectorised on the strided image the cloud is built from (320x240 by default):
a few dozen array operations and one ``cv2.connectedComponents``. Time comes from the frame
stamps; a stamp going back (a bag loop) does not move the model's clock back.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np

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
#: Neighbouring depths differing by more than ``(EDGE_STEP + EDGE_STEP_Z * z) * stride``
#: metres are a depth edge between two components (a limb's grazing side at 4 m differs by
#: less; a person 10 cm in front of a chair by more).
EDGE_STEP = 0.1
EDGE_STEP_Z = 0.03
#: Farther readings adopted within this time count towards camera motion.
RECENT_FAR_S = 0.25
#: Camera motion is only judged when this fraction of the image has a known background.
MIN_KNOWN_FRACTION = 0.1
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


def depth_components(depth: npt.NDArray[np.float32], mask: npt.NDArray[np.bool_],
                     stride: int, far_side: npt.NDArray[np.bool_] | None = None,
                     ) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.bool_]]:
    """Connected parts of ``mask`` split at depth edges.

    ``depth`` (H, W) metres with 0 or NaN where there is no reading, ``mask`` (H, W) the
    pixels to label, ``stride`` the pixel stride of the image (neighbours are that many
    full-resolution pixels apart). A pixel whose 4-neighbour is nearer by more than the edge
    step is the far side of an edge and is left out; 4-connectivity then cannot cross the
    edge. ``far_side``: :func:`far_side_pixels` of the same image, when the caller labels
    several masks of it. Returns the labels (0: none) and the left-out far-side pixels of
    ``mask``.
    """
    if far_side is None:
        far_side = far_side_pixels(depth, stride)
    far = far_side & mask
    _, labels = cv2.connectedComponents((mask & ~far).view(np.uint8), connectivity=4,
                                        ltype=cv2.CV_32S)
    return labels, far


def far_side_pixels(depth: npt.NDArray[np.float32], stride: int) -> npt.NDArray[np.bool_]:
    """(H, W) pixels of ``depth`` with a 4-neighbour nearer by more than the edge step
    (``(EDGE_STEP + EDGE_STEP_Z * z) * stride`` metres): the far sides of depth edges."""
    z = np.where(np.isfinite(depth) & (depth > 0), depth, np.inf).astype(np.float32)
    step = np.float32((EDGE_STEP + EDGE_STEP_Z * np.minimum(z, 20.0)) * stride)
    lower = z - step  # a neighbour below this is nearer by more than the step
    far = np.zeros(z.shape, dtype=bool)
    far[:, :-1] |= z[:, 1:] < lower[:, :-1]
    far[:, 1:] |= z[:, :-1] < lower[:, 1:]
    far[:-1, :] |= z[1:, :] < lower[:-1, :]
    far[1:, :] |= z[:-1, :] < lower[1:, :]
    return far


def _windows(image: npt.NDArray, uv: npt.NDArray[np.int64]) -> npt.NDArray:
    """(N, (2r + 1)^2) values of ``image`` around N pixels (u, v), r = PROTECT_RADIUS_PX,
    clipped at the border."""
    h, w = image.shape
    offsets = np.arange(-PROTECT_RADIUS_PX, PROTECT_RADIUS_PX + 1)
    uu = np.clip(uv[:, 0, None, None] + offsets[None, None, :], 0, w - 1)
    vv = np.clip(uv[:, 1, None, None] + offsets[None, :, None], 0, h - 1)
    return image[vv, uu].reshape(len(uv), len(offsets) ** 2)


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
        self._clear()

    def _clear(self) -> None:
        self._bg: npt.NDArray[np.float32] | None = None
        self._fg_ids: dict[int, float] = {}  # tracks that sat on a moving component: since
        self._carried: set[int] = set()  # those of them alive when the camera moved
        self._carried_uv = np.zeros((0, 2), np.int64)  # their pixels in the last frame
        self._labels: npt.NDArray[np.int32] | None = None
        self._learn_until = 0.0
        self._last_raw: float | None = None
        self._offset = 0.0
        self._t = 0.0

    def reset(self) -> None:
        """Re-learn from the next frame (the ``reset_background`` service). Only sets a flag,
        so it may be called from another thread than :meth:`foreground`'s."""
        self._reset_requested = True

    @property
    def learning(self) -> bool:
        """True while everything is still kept (the first ``background_learn_s``)."""
        return self._bg is None or self._t < self._learn_until

    @property
    def background(self) -> npt.NDArray[np.float32] | None:
        """(H, W) background depth of the strided image, metres (0: not known), or None."""
        return self._bg

    def _clock(self, stamp_ns: int) -> float:
        """Model time (s): the stamp, never going back (a bag loop continues the clock)."""
        raw = stamp_ns * 1e-9
        if self._last_raw is not None and raw < self._last_raw:
            self._offset += self._last_raw - raw
        self._last_raw = raw
        self._t = max(self._t, raw + self._offset)
        return self._t

    def _learn(self, depth: npt.NDArray[np.float32], valid: npt.NDArray[np.bool_],
               t: float, params: EndeffParams) -> None:
        """Start learning from ``depth``: the background is the current frame."""
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
        self._static_z = np.zeros(shape, np.float32)
        self._static_since = np.zeros(shape, np.float64)
        self._moving_labels = np.zeros(1, bool)
        self._out = np.zeros(shape, bool)
        self._learn_until = t + params.background_learn_s
        self._settling = False

    def foreground(self, depth: npt.NDArray[np.floating], candidate: npt.NDArray[np.bool_],
                   stamp_ns: int, params: EndeffParams, *,
                   low: npt.NDArray[np.bool_] | None = None) -> npt.NDArray[np.bool_]:
        """Learn from one frame and return the pixels of ``candidate`` that are foreground.

        ``depth`` (H, W) metres (0, NaN, inf: no reading; the caller zeroes readings beyond the
        sensor's range) is the strided image Section 3 builds the
        cloud from (``params.pixel_stride``), ``candidate`` (H, W) its pixels inside the box
        and off the floor; ``stamp_ns`` the frame's stamp; ``low`` (H, W) optional, the
        candidate pixels just above the floor, which do not connect components (the floor's
        noisy remnants would join a person's feet to a chair's legs) and are kept next to a
        kept pixel. Returns an (H, W) mask, a subset of ``candidate``.
        """
        d = np.nan_to_num(np.asarray(depth, dtype=np.float32), nan=0.0, posinf=0.0,
                          neginf=0.0)
        valid = d > 0
        d[~valid] = 0
        t = self._clock(stamp_ns)
        stride = params.pixel_stride
        if self._reset_requested or self._bg is None or self._bg.shape != d.shape:
            self.resets += self._reset_requested
            self._reset_requested = False
            self._learn(d, valid, t, params)
            self._labels, _ = depth_components(d, candidate, stride)
            return candidate.copy()
        bg = self._bg
        known = valid & (bg > 0)
        margin = np.float32(params.background_margin) + np.float32(NOISE_Z2) * bg * bg
        nearer = known & (d < bg - margin)
        farther = known & (d > bg + margin)

        n_known = int(np.count_nonzero(known))
        if n_known >= MIN_KNOWN_FRACTION * d.size:
            recent_far = farther | (self._far_t > t - RECENT_FAR_S)
            f = params.background_camera_motion_fraction * n_known
            if self._settling and t < self._learn_until:
                f /= SETTLING_DIVISOR
            if np.count_nonzero(nearer) >= f and np.count_nonzero(recent_far & known) >= f:
                if not (self._settling and t < self._learn_until):
                    # The turn begins (tracks that became foreground as it began sit on
                    # furniture): these tracks are carried through it.
                    self._carried |= {i for i, since in self._fg_ids.items()
                                      if since <= t - CARRY_AFTER_S}
                self.relearns += 1
                self._learn(d, valid, t, params)
                self._settling = True
                self._labels, _ = depth_components(d, candidate, stride)
                return candidate.copy()

        # Farther readings, and readings where nothing was seen yet (no reading is beyond
        # the sensor's range: the farthest of all), are adopted once FAR_FRAMES consecutive
        # frames agree; until then a reading where nothing was seen counts as changed (a
        # person in front of a hall too deep for the sensor).
        fresh = valid & ~known
        pending = farther | fresh
        agree = pending & (self._far_n > 0) & (np.abs(d - self._far_ref) <= margin)
        self._far_n = np.where(pending, np.where(agree, self._far_n + 1, 1), 0).astype(np.int16)
        self._far_ref = np.where(pending & ~agree, d, self._far_ref)
        adopt = self._far_n >= FAR_FRAMES
        # Readings within the margin: the running mean follows them.
        steady = known & ~nearer & ~farther
        bg = np.where(steady, bg + np.float32(FOLLOW) * (d - bg), bg)
        bg = np.where(adopt, d, bg).astype(np.float32)
        self._far_t = np.where(adopt & known, t, self._far_t)
        self._far_n[adopt] = 0
        # No reading for MISS_FRAMES frames: what was there left, nothing is seen behind it
        # (not after a few frames: dark or glossy surfaces drop out now and then).
        self._miss_n = np.where(valid | (bg <= 0), 0, self._miss_n + 1).astype(np.int16)
        bg[self._miss_n >= MISS_FRAMES] = 0
        # Nearer readings: absorbed after background_absorb_s at a steady depth.
        same = nearer & (np.abs(d - self._near_ref) <= margin)
        self._near_since = np.where(same, self._near_since, t)
        self._near_ref = np.where(nearer & ~same, d, self._near_ref)
        absorb = nearer & (t - self._near_since >= params.background_absorb_s)
        bg[absorb] = d[absorb]
        self._bg = bg

        upper = candidate if low is None else candidate & ~low
        far_side = far_side_pixels(d, stride)
        labels, edge = depth_components(d, upper, stride, far_side)
        self._labels = labels
        if t < self._learn_until:
            return candidate.copy()
        changed = cv2.morphologyEx(((nearer & ~absorb) | (fresh & ~adopt)).view(np.uint8),
                                   cv2.MORPH_OPEN,
                                   np.ones((3, 3), np.uint8)).view(bool)
        n = int(labels.max()) + 1
        total = np.bincount(labels.ravel(), minlength=n)
        hits = np.bincount(labels[changed], minlength=n)
        need = np.maximum(MIN_CHANGED_PX / stride ** 2, MIN_CHANGED_FRACTION * total)
        moving = hits >= need
        moving[0] = False
        # Held: pixels kept because of changed pixels within HOLD_S, at the same depth (the
        # same surface, not the wall an arm swept over).
        recent = (t - self._kept_t <= HOLD_S) & (np.abs(d - self._kept_z) <= margin)
        held = np.bincount(labels[recent], minlength=n) >= HOLD_FRACTION * total
        # Only components with changed pixels renew the hold, and not on pixels certifying
        # as static (furniture that a noisy edge joined to a person for a frame).
        certifying = (self._static_z > 0) & (np.abs(d - self._static_z) <= margin)
        renew = moving[labels] & ~certifying
        self._kept_t[renew] = t
        self._kept_z[renew] = d[renew]
        self._moving_labels = moving
        keep = moving | held
        keep[self._track_labels(labels, self._carried_uv)] = True
        keep[0] = False
        fg = keep[labels] & candidate
        # Certified static: pixels that were dropped for STATIC_S at the same depth stay
        # dropped when a moving component joins them (furniture a person stands next to).
        margin_ok = np.abs(d - self._static_z) <= margin
        start = candidate & ~fg & ~((self._static_z > 0) & margin_ok)
        self._static_z[start] = d[start]
        self._static_since[start] = t
        # That surface is gone: something changed in front of it, or it left (a single
        # flying pixel at an edge does neither: the opening removed it from changed).
        gone = fg & ~margin_ok & (changed | (d > self._static_z + margin))
        self._static_z[gone] = 0
        static = (self._static_z > 0) & margin_ok & (t - self._static_since >= STATIC_S)
        out = (fg & ~(static & ~changed)) | (edge & changed)
        if low is not None:
            # Feet: the parts of the band just above the floor (split at depth edges) that
            # touch a kept pixel at their depth (not the wall's foot beside a person's legs).
            box = np.ones((3, 3), np.uint8)
            hi = cv2.dilate(np.where(out, d, 0).astype(np.float32), box)
            lo = cv2.erode(np.where(out, d, np.inf).astype(np.float32), box)
            step = np.float32(EDGE_STEP + EDGE_STEP_Z * 3.0) * stride
            low_labels, _ = depth_components(d, low & candidate, stride, far_side)
            touch = (low_labels > 0) & (d >= lo - step) & (d <= hi + step)
            attached = np.zeros(int(low_labels.max()) + 1, bool)
            attached[low_labels[touch]] = True
            attached[0] = False
            out |= attached[low_labels] | (low & candidate & changed)
        self._out = out
        return out

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
                intrinsics: Intrinsics, stride: int) -> None:
        """Tell the model where the tracks are: ``positions`` (N, 3) metres, optical frame,
        the surface anchors of the tracks with ``ids`` after the last frame. Their
        components restart the absorption clock (a tracked person standing still is not
        absorbed). The tracks that sat on a component with changed pixels when the camera
        moved keep their components foreground while they live: a person who stands still
        while the camera turns is not dropped when the learning after the turn ends, while
        tracks started on furniture during that learning do not count (only a camera motion
        carries tracks: otherwise a track that once sat on a moving chair would keep it
        for good). ``stride``: the pixel stride the last frame was labelled at."""
        labels = self._labels
        if labels is None or self._bg is None:
            return
        pts = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        track_ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        with np.errstate(divide='ignore', invalid='ignore'):
            u = np.round((intrinsics.fx * pts[:, 0] / pts[:, 2] + intrinsics.cx) / stride)
            v = np.round((intrinsics.fy * pts[:, 1] / pts[:, 2] + intrinsics.cy) / stride)
        ok = (pts[:, 2] > 1e-6) & np.isfinite(u) & np.isfinite(v)
        uv = np.stack([u[ok], v[ok]], axis=1).astype(np.int64)
        track_ids = track_ids[ok]
        hit = self._track_labels(labels, uv)
        if hit.any():
            self._near_since[np.isin(labels, hit[hit > 0])] = self._t
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
        self._carried_uv = uv[np.isin(track_ids, list(self._carried))]
