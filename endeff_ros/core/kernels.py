"""Compiled kernels for the loops numpy cannot fuse (optional: numba).

The static background (:mod:`.background`) and its depth edges (:mod:`.depth_edges`) update
a dozen per-pixel states of the strided image every frame: in numpy each rule is a pass over
the whole image and an allocation, some sixty of them a frame at 20-60 µs each. The band
expansion (:func:`.bands.expand_bands`) costs a dozen small array operations a band. These
kernels run the same rules in one loop per stage. They are compiled with numba when it is
installed (PyPI ``numba``, Ubuntu's ``python3-numba``) and the environment does not set
``ENDEFF_NUMBA=0``; otherwise :data:`ENABLED` is False and the callers run their numpy code,
which stays the reference: ``test/test_kernels.py`` checks that both give the same arrays,
and ``tools.fingerprint`` that both publish the same end-effectors.

Arithmetic follows numpy's exactly: float32 where the arrays are float32 (the constants come
in as float32 arguments, never Python floats, which numba would widen to float64), float64
for the clocks. numba caches the compiled code beside this module (or in its user cache when
that is not writable): a machine compiles once, and a process then loads the code at its
first call of each kernel, which :func:`warm_up` makes before the first frame.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import os
import signal
import threading
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from collections.abc import Iterator

#: Whether the compiled kernels run: numba is installed and ``ENDEFF_NUMBA`` is not ``0``
#: (callers test it at each call; the tests switch it off to compare with the numpy code).
#: numba is imported at the first call, not with this module (it costs a quarter of a
#: second, which commands that never reach the background need not pay); if that import
#: fails (a numba built for another numpy), this turns False with one warning.
ENABLED = (os.environ.get('ENDEFF_NUMBA', '1') != '0'
           and importlib.util.find_spec('numba') is not None)


class _Compiled:
    """A kernel compiled with numba at its first call (:data:`ENABLED`)."""

    def __init__(self, fn: Any) -> None:
        self._fn = fn
        self._run: Any = None
        self.__doc__ = fn.__doc__

    def __call__(self, *args: Any) -> Any:
        if self._run is not None:
            return self._run(*args)
        with _signals_held():  # numba compiles, or loads its cache, in this first call
            run = self._compile()
            out = run(*args)
        self._run = run
        return out

    def _compile(self) -> Any:
        global ENABLED
        try:
            import numba
        except Exception as e:  # noqa: BLE001 - any failure of a broken install: numpy runs
            logging.getLogger('endeff_ros').warning(
                'numba does not import (%s): the numpy code runs instead', e)
            ENABLED = False
            return self._fn  # this call only: the callers test ENABLED from now on
        return numba.njit(cache=True, nogil=True)(self._fn)


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """SIGINT and SIGTERM kept out of llvmlite while numba compiles: raised in one of its
    ctypes callbacks, their exception would be printed and swallowed, and the command would
    go on. A signal that comes while llvmlite's code runs is sent again once the compilation
    is over; elsewhere its handler runs at once (a first compilation takes seconds). The main
    thread only: no other thread runs signal handlers."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    held = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.getsignal(s) for s in held}

    def hold(signum: int, frame: Any) -> None:
        if _in_llvmlite(frame):
            caught.append(signum)
            return
        handler = previous[signum]
        if callable(handler):
            handler(signum, frame)
        elif handler != signal.SIG_IGN:  # the default action (set outside Python: None)
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)

    for s in held:
        signal.signal(s, hold)
    try:
        yield
    finally:
        for s, handler in previous.items():
            if signal.getsignal(s) is hold:  # not where a handler set another (SIG_IGN once run)
                signal.signal(s, signal.SIG_DFL if handler is None else handler)
        for s in dict.fromkeys(caught):
            if previous[s] != signal.SIG_IGN:
                os.kill(os.getpid(), s)


def _in_llvmlite(frame: Any) -> bool:
    """Whether ``frame`` or a caller of it runs llvmlite's code."""
    while frame is not None:
        if f'{os.sep}llvmlite{os.sep}' in frame.f_code.co_filename:
            return True
        frame = frame.f_back
    return False


#: A stand-in for an unused per-pixel mask argument (the kernels do not read it).
NO_PIXELS = np.zeros((1, 1), bool)


@_Compiled
def bridge_and_far_side(d, mask, step0, step_z, stride, fraction, bridge, flying,
                        out_z, out_mask, out_far):  # pragma: no cover - compiled
    """:func:`.depth_edges.bridge_dropouts` of ``d`` (0: no reading) and ``mask``, into
    ``out_z`` and ``out_mask``, then :func:`.depth_edges.far_side_pixels` of the bridged
    depths into ``out_far`` (flying pixels with ``flying``). The float32 constants: the edge
    step's ``step0`` and ``step_z``, the ``stride``, ``FLYING_FRACTION``, ``BRIDGE_STEP``."""
    h, w = d.shape
    inf = np.float32(np.inf)
    zero = np.float32(0.0)
    for r in range(h):
        for c in range(w):
            z = d[r, c]
            out_z[r, c] = z
            out_mask[r, c] = mask[r, c]
            if z <= 0:
                near = inf
                far = zero
                for rr in range(max(r - 1, 0), min(r + 2, h)):
                    for cc in range(max(c - 1, 0), min(c + 2, w)):
                        if mask[rr, cc]:
                            v = d[rr, cc]
                            near = min(near, v)
                            far = max(far, v)
                if near < inf and far - near <= bridge:
                    out_z[r, c] = near
                    out_mask[r, c] = True
    twenty = np.float32(20.0)
    for r in range(h):
        for c in range(w):
            z = out_z[r, c]
            if not (z > 0 and z < inf):
                z = inf
            step = (step0 + step_z * min(z, twenty)) * stride
            lo = inf
            hi = zero
            for k in range(4):
                rr = r - 1 if k == 0 else r + 1 if k == 1 else r
                cc = c - 1 if k == 2 else c + 1 if k == 3 else c
                if 0 <= rr < h and 0 <= cc < w:
                    v = out_z[rr, cc]
                    if v > 0 and v < inf:
                        lo = min(lo, v)
                        hi = max(hi, v)
            far_side = lo < z - step
            if not far_side and flying:
                side = fraction * step
                far_side = hi - lo > step and z - lo > side and hi - z > side
            out_far[r, c] = far_side


@_Compiled
def update_depths(d, valid, known, nearer, farther, margin, bg, far_n, far_ref, far_t,
                  miss_n, near_ref, near_since, t, absorb_s, follow, far_frames, miss_frames,
                  new_bg, changed, adopt):  # pragma: no cover - compiled
    """The background depth's update of :meth:`.background.BackgroundModel.foreground`
    (farther readings adopted, the running mean, readings missed, nearer ones absorbed): the
    states ``far_n`` ... ``near_since`` in place, the new background into ``new_bg``, the
    pixels adopted into ``adopt`` and the changed pixels before the opening into ``changed``
    (uint8, 1: nearer and not absorbed, or read where nothing was and not adopted)."""
    h, w = d.shape
    for r in range(h):
        for c in range(w):
            z = d[r, c]
            m = margin[r, c]
            b = bg[r, c]
            fresh = valid[r, c] and not known[r, c]
            pending = farther[r, c] or fresh
            n = far_n[r, c]
            if pending:
                if n > 0 and abs(z - far_ref[r, c]) <= m:  # agrees: one more frame
                    n += 1
                else:
                    n = 1
                    far_ref[r, c] = z
            else:
                n = 0
            taken = n >= far_frames
            if known[r, c] and not nearer[r, c] and not farther[r, c]:
                b = b + (z - b) * follow
            if taken:
                b = z
                if known[r, c]:
                    far_t[r, c] = t
                n = 0
            far_n[r, c] = n
            adopt[r, c] = taken
            missed = miss_n[r, c] + 1 if (not valid[r, c] and b > 0) else 0
            miss_n[r, c] = missed
            if missed >= miss_frames:
                b = np.float32(0.0)
            absorbed = False
            if nearer[r, c]:
                if not abs(z - near_ref[r, c]) <= m:
                    near_since[r, c] = t
                    near_ref[r, c] = z
                absorbed = t - near_since[r, c] >= absorb_s
                if absorbed:
                    b = z
            else:
                near_since[r, c] = t
            new_bg[r, c] = b
            changed[r, c] = 1 if ((nearer[r, c] and not absorbed) or (fresh and not taken)) else 0


@_Compiled
def label_counts(labels, changed, stirred, use_stirred, d, kept_t, kept_z, margin, t, hold_s,
                 n_changed, n_stirred, n_recent):  # pragma: no cover - compiled
    """Per label of ``labels``, its pixels that ``changed``, that ``stirred`` (with
    ``use_stirred``) and that were held within ``hold_s`` at their depth (``kept_t``,
    ``kept_z``), added into ``n_changed``, ``n_stirred`` and ``n_recent``."""
    h, w = labels.shape
    for r in range(h):
        for c in range(w):
            k = labels[r, c]
            if changed[r, c]:
                n_changed[k] += 1
            if use_stirred and stirred[r, c]:
                n_stirred[k] += 1
            if t - kept_t[r, c] <= hold_s and abs(d[r, c] - kept_z[r, c]) <= margin[r, c]:
                n_recent[k] += 1


@_Compiled
def certify(labels, moving, by_colour, use_colour, keep, candidate, d, margin, changed, edge,
            there, stirred_near, colour_t, colour_z, kept_t, kept_z, static_z, static_since, t,
            confirm_s, static_s, out):  # pragma: no cover - compiled
    """:meth:`.background.BackgroundModel._certify`: the hold renewed (``kept_t``,
    ``kept_z``), the colour's confirmation (``colour_t``, ``colour_z``, with
    ``use_colour``), static surfaces certified and released (``static_z``,
    ``static_since``), in place; the foreground into ``out``."""
    h, w = labels.shape
    for r in range(h):
        for c in range(w):
            k = labels[r, c]
            z = d[r, c]
            m = margin[r, c]
            renew = moving[k]
            if use_colour and by_colour[k]:
                if t - colour_t[r, c] <= confirm_s and abs(z - colour_z[r, c]) <= m:
                    renew = True
                colour_t[r, c] = t
                colour_z[r, c] = z
            margin_ok = abs(z - static_z[r, c]) <= m
            certifying = static_z[r, c] > 0 and margin_ok
            if renew and not certifying:
                kept_t[r, c] = t
                kept_z[r, c] = z
            fg = keep[k] and candidate[r, c]
            if candidate[r, c] and not fg and not certifying:
                static_z[r, c] = z
                static_since[r, c] = t
            cut = changed[r, c]
            gone = fg and not margin_ok and (cut or z > static_z[r, c] + m)
            if use_colour and fg and stirred_near[r, c]:
                if margin_ok:
                    static_since[r, c] = t
                else:
                    gone = True
            if gone:
                static_z[r, c] = np.float32(0.0)
            static = (static_z[r, c] > 0 and margin_ok and t - static_since[r, c] >= static_s
                      and not there[r, c])
            out[r, c] = (fg and not (static and not cut)) or (edge[r, c] and cut)


@_Compiled
def grow_bands(indptr, indices, data, dense, band, curve, rim, k, max_k, mark, close, new,
               contour):  # pragma: no cover - compiled
    """The narrow bands of :func:`.bands.expand_bands` from the contour ``curve`` (Eqs. 1-4),
    numbered from ``k + 1`` into ``band`` (-1: unreached) until the front dies or band
    ``max_k`` is reached; returns the last band's number. The graph is the CSR
    (``indptr``, ``indices``, ``data``); ``rim`` is ¾δ_L; ``mark`` and ``close`` (N, False)
    and ``new`` and ``contour`` (N) are scratch."""
    m = curve.shape[0]
    contour[:m] = curve
    while k < max_k:
        n_new = 0
        for a in range(m):
            p = contour[a]
            for e in range(indptr[p], indptr[p + 1]):
                q = indices[e]
                if band[q] == -1 and dense[q]:
                    if not mark[q]:
                        mark[q] = True
                        new[n_new] = q
                        n_new += 1
                    if data[e] < rim:
                        close[q] = True  # φ < ¾δ_L: not on the next contour (Eq. 4)
        if n_new == 0:
            return k
        k += 1
        m = 0
        for b in range(n_new):
            q = new[b]
            band[q] = k
            mark[q] = False
            if not close[q]:
                contour[m] = q
                m += 1
        if m == 0:
            contour[:n_new] = new[:n_new]
            m = n_new
        for b in range(n_new):
            close[new[b]] = False
    return k


@_Compiled
def confirm(labels, held, parts, use_parts, learning, counted, flagged, votes, pixels, depth,
            t, near_since, init_z, init_seen, init_votes):  # pragma: no cover - compiled
    """:meth:`.background.BackgroundModel._confirm`, in place on ``near_since``, ``init_z``,
    ``init_seen`` and ``init_votes``; per label ``held``, ``parts`` (with ``use_parts``),
    ``counted`` and ``flagged`` (with ``votes``), per pixel the person's ``pixels``."""
    h, w = labels.shape
    for r in range(h):
        for c in range(w):
            k = labels[r, c]
            on = held[k]
            if on:
                near_since[r, c] = t
            part = use_parts and parts[k]
            if learning and (on or part) and init_z[r, c] == 0 and depth[r, c] > 0:
                init_z[r, c] = depth[r, c]
            if votes and init_z[r, c] > 0:
                if counted[k]:
                    init_seen[r, c] += 1
                voted = flagged[k]
                if use_parts:
                    voted = (voted or part) and pixels[r, c]
                if voted:
                    init_votes[r, c] += 1


def warm_up() -> None:
    """Compile the kernels (or load them from the cache) on a 2x2 image, with the types the
    callers pass: a process's first frames then pay no compilation."""
    if not ENABLED:
        return
    f32 = np.float32
    z = np.ones((2, 2), f32)
    yes = np.ones((2, 2), bool)
    ticks = np.zeros((2, 2), np.float64)
    count = np.zeros((2, 2), np.int16)
    bridge_and_far_side(z, yes, f32(0.1), f32(0.03), f32(2), f32(0.25), f32(0.1), True,
                        z.copy(), yes.copy(), yes.copy())
    update_depths(z, yes, yes, ~yes, ~yes, z * f32(0.01), z, count, z.copy(), ticks, count.copy(),
                  z.copy(), ticks.copy(), 0.0, 1.0, f32(0.05), 3, 15, z.copy(),
                  np.zeros((2, 2), np.uint8), yes.copy())
    n = np.zeros(1, np.int64)
    labels = np.zeros((2, 2), np.int32)
    label_counts(labels, yes, yes, True, z, ticks, z, z, 0.0, 0.5, n, n.copy(), n.copy())
    one = np.ones(1, bool)
    certify(labels, one, one, True, one, yes, z, z, yes, yes, yes, yes, ticks, z.copy(),
            ticks.copy(), z.copy(), z.copy(), ticks.copy(), 0.0, 0.2, 0.25, yes.copy())
    count16 = np.zeros((2, 2), np.uint16)
    confirm(labels, one, one, True, True, one, one, True, yes, z, 0.0, ticks.copy(), z.copy(),
            count16, count16.copy())
    index = np.zeros(2, np.intp)
    grow_bands(index, index[:0], np.zeros(0), one, np.zeros(1, np.intp), index[:1], 0.06, 0,
               10, ~one, ~one, index.copy(), index.copy())
