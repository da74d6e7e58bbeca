"""The compiled kernels (core/kernels.py) against the numpy code they replace: the same arrays
and the same foreground, frame after frame; and the package without them."""

from __future__ import annotations

import copy
import dataclasses
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from test_background import PARAMS, PERSON_Z, add_chair, add_person, frame, room

from endeff_ros import cli_common, workers
from endeff_ros.core import bands, kernels
from endeff_ros.core.background import BackgroundModel
from endeff_ros.core.depth_edges import bridged_edges
from endeff_ros.core.single_frame import estimate_frame
from endeff_ros.core.types import KINECT_640 as K
from endeff_ros.core.types import RGBDFrame

compiled = pytest.mark.skipif(not kernels.ENABLED, reason='numba is not installed')


def _patchwork(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Depth (float32, 0: no reading) of rectangles at random depths over a slanted wall,
    with single-pixel dropouts and flying pixels between them."""
    h, w = shape
    depth = np.broadcast_to(np.linspace(2.0, 5.0, w, dtype=np.float32), shape).copy()
    for _ in range(12):
        r, c = rng.integers(0, h - 10), rng.integers(0, w - 10)
        depth[r:r + rng.integers(3, 40), c:c + rng.integers(3, 40)] = rng.uniform(0.5, 6.0)
    flying = rng.random(shape) < 0.05
    depth[flying] = (depth[flying] + np.roll(depth, 1, axis=1)[flying]) / 2
    depth[rng.random(shape) < 0.08] = 0
    depth[:, :3] = 0  # a dead margin
    return depth.astype(np.float32)


@compiled
@pytest.mark.parametrize('stride', [1, 2, 3])
@pytest.mark.parametrize('flying', [False, True])
def test_bridged_edges_compiled_equals_numpy(stride, flying, monkeypatch):
    rng = np.random.default_rng(stride + 10 * flying)
    depth = _patchwork(rng, (120, 160))
    mask = (depth > 0) & (rng.random(depth.shape) < 0.9)
    got = bridged_edges(depth, mask, stride, flying=flying)
    monkeypatch.setattr(kernels, 'ENABLED', False)
    want = bridged_edges(depth, mask, stride, flying=flying)
    assert want[1].sum() > mask.sum()  # some dropouts were bridged
    assert want[2].any()  # and edges found
    for a, b in zip(got, want):
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)


def _scene(k: int, rng: np.random.Generator, colour: bool) -> RGBDFrame:
    """A person who waves for a second, then stands still (absorbed when untracked), a
    second one still from the start, a chair that is carried off after 1.2 s (its place read
    farther: adopted), a patch that stops reading after 0.5 s (missed), random dropouts; with
    ``colour`` a textured image whose first person's part moves with them (stirred)."""
    depth = room().copy()
    if k < 36:
        add_chair(depth)
    x = -0.5 + (0.15 * np.sin(k / 9.0) if k < 30 else 0.0)
    add_person(depth, x, 0.5 + 0.5 * np.sin(min(k, 30) / 5.0))
    add_person(depth, 1.3, 0.0)
    f = frame(k, depth)
    f.depth[rng.random(depth.shape) < 0.01] = 0  # after the noise, which reads zeros
    if k >= 15:
        f.depth[40:100, 10:70] = 0  # a patch of the wall
    if not colour:
        return f
    image = TEXTURE[:, 32:32 + K.width].copy()
    person = (np.abs(depth - PERSON_Z) < 0.01) & (np.arange(K.width) < K.width // 2 + 100)
    shift = int(round(K.fx * (x + 0.5) / PERSON_Z))
    image[person] = TEXTURE[:, 32 - shift:32 - shift + K.width][person]
    return dataclasses.replace(f, color=image)


TEXTURE = np.random.default_rng(0).integers(0, 256, (K.height, K.width + 64, 3), np.uint8)


def _run(enabled: bool, colour: bool, keep_initial: bool, monkeypatch) -> list[tuple]:
    monkeypatch.setattr(kernels, 'ENABLED', enabled)
    model = BackgroundModel()
    rng = np.random.default_rng(3)
    params = PARAMS.replace(background_keep_initial=keep_initial)
    out = []
    for k in range(75):
        est = estimate_frame(_scene(k, rng, colour), params, background=model)
        out.append((est.points.copy(), model.background.copy(), model._kept_t.copy(),
                    model._kept_z.copy(), model._static_z.copy(), model._static_since.copy(),
                    model._colour_t.copy(), model._colour_z.copy(), model._near_since.copy(),
                    model._far_n.copy()))
    return out


@compiled
@pytest.mark.parametrize('colour', [False, True])
@pytest.mark.parametrize('keep_initial', [False, True])
def test_foreground_compiled_equals_numpy(colour, keep_initial, monkeypatch):
    """Over 2.5 s of a scene that uses every rule of the update (followed, adopted, missed,
    absorbed, held, stirred), the compiled kernels give the numpy code's foreground and
    per-pixel states in every frame."""
    got = _run(True, colour, keep_initial, monkeypatch)
    want = _run(False, colour, keep_initial, monkeypatch)
    assert len(want[-1][0]) < len(want[0][0])  # the background removed something
    for k, (a, b) in enumerate(zip(got, want)):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y, err_msg=f'frame {k}')


def test_the_package_runs_without_numba():
    """``ENDEFF_NUMBA=0`` (as without numba installed): the numpy code runs."""
    code = ('from endeff_ros.core import kernels; assert not kernels.ENABLED; '
            'from endeff_ros.core.warmup import warm_up; '
            'from endeff_ros.core.tracker import Tracker; print(warm_up(Tracker()))')
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          env={**os.environ, 'ENDEFF_NUMBA': '0'}, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    assert int(done.stdout.split()[-1]) > 0


def _states(model: BackgroundModel) -> list[np.ndarray]:
    return [model._far_n, model._far_ref, model._far_t, model._miss_n, model._near_ref,
            model._near_since]


@compiled
def test_update_and_counts_compiled_equal_numpy(monkeypatch):
    """The background's update and the per-label counts on random frames around a learnt
    background (every pixel nearer, farther, within the margin or without a reading, at
    random), in both codes from the same state: the same outputs and states."""
    rng = np.random.default_rng(5)
    shape = (60, 80)
    model = BackgroundModel()
    first = _patchwork(rng, shape)
    model.foreground(first, first > 0, 0, PARAMS)
    twin = copy.deepcopy(model)
    for k in range(1, 40):
        t = k / 10.0  # a clock fast enough to absorb, adopt and miss within the run
        steps = [-0.5, -0.03, -0.004, 0.0, 0.004, 0.03, 0.5]
        step = rng.choice(steps, size=shape).astype(np.float32)
        depth = np.where(rng.random(shape) < 0.3, first + step, model._bg + step / 4)
        depth[rng.random(shape) < 0.1] = 0
        depth[:20, :20] = first[:20, :20] * 0.8  # something nearer that stays: absorbed
        depth[40:, 70:] = 0  # no reading any more: missed
        depth = depth.astype(np.float32)
        labels = rng.integers(0, 6, shape).astype(np.int32)
        stirred = rng.random(shape) < 0.2
        kept = rng.random(shape) < 0.3
        outs = []
        for enabled, m in ((True, model), (False, twin)):
            monkeypatch.setattr(kernels, 'ENABLED', enabled)
            valid = depth > 0
            known = valid & (m._bg > 0)
            margin = np.float32(0.02) + np.zeros(shape, np.float32)
            nearer = known & (depth < m._bg - margin)
            farther = known & (depth > m._bg + margin)
            bg, adopt, changed = m._update_depths(depth, valid, known, nearer, farther, margin,
                                                  t, PARAMS)
            m._bg = bg
            m._kept_t[kept] = t - 0.3
            counts = m._label_counts(labels, changed.view(bool), stirred, depth, margin, t, 6)
            outs.append([bg, adopt, changed, *counts, *_states(m)])
        for a, b in zip(*outs):
            np.testing.assert_array_equal(a, b)
    assert np.array_equal(model._bg[:20, :20], depth[:20, :20])  # absorbed
    assert not model._bg[40:, 70:].any()  # missed


@compiled
@pytest.mark.parametrize('colour', [False, True])
def test_certify_compiled_equals_numpy(colour, monkeypatch):
    """The per-pixel rules after the labels' verdicts on random inputs and states (every
    branch: renewed by changes or by colour, certifying, started, gone, stirred near, static
    or an entity of the start's), in both codes from the same state."""
    rng = np.random.default_rng(7 + colour)
    shape = (60, 80)
    model = BackgroundModel()
    first = _patchwork(rng, shape)
    model.foreground(first, first > 0, 0, PARAMS)
    model._static_z[:] = np.where(rng.random(shape) < 0.5, first, 0)
    twin = copy.deepcopy(model)
    for k in range(1, 30):
        t = k / 10.0
        d = np.where(rng.random(shape) < 0.5, first, first + np.float32(0.05)).astype(np.float32)
        margin = np.full(shape, 0.02, np.float32)
        labels = rng.integers(0, 8, shape).astype(np.int32)
        per_label = rng.random((3, 8)) < 0.5
        pixels = rng.random((5, *shape)) < 0.5
        clocks = t - rng.choice([0.0, 0.1, 0.3, 1.0], size=(2, *shape))
        outs = []
        for enabled, m in ((True, model), (False, twin)):
            monkeypatch.setattr(kernels, 'ENABLED', enabled)
            m._colour_t[pixels[4]] = clocks[0][pixels[4]]
            m._static_since[pixels[3]] = clocks[1][pixels[3]]
            out = m._certify(labels, per_label[0], per_label[1] if colour else None,
                             per_label[2], pixels[0], d, margin, pixels[1], pixels[2],
                             pixels[3], pixels[4] if colour else None, t)
            outs.append([out, m._colour_t, m._colour_z, m._kept_t, m._kept_z, m._static_z,
                         m._static_since])
        assert outs[1][0].any() and not outs[1][0].all()
        for a, b in zip(*outs):
            np.testing.assert_array_equal(a, b, err_msg=f'frame {k}')


@compiled
@pytest.mark.parametrize('seed', [0, 1, 3])
@pytest.mark.parametrize('max_bands', [None, 3])
def test_bands_compiled_equal_numpy(seed, max_bands, monkeypatch):
    """The compiled band loop gives the numpy expansion's bands and bridges: on clouds of
    blobs and limbs with sparse points (the density test), parts across an occlusion gap
    (bridged) and parts joined off the contour (leaks)."""
    rng = np.random.default_rng(seed)
    parts = [rng.normal(c, s, (n, 3)) for c, s, n in (
        ([0, 0, 2], [0.1, 0.2, 0.05], 600), ([0.3, 0.1, 2], [0.15, 0.02, 0.02], 150),
        ([0.95, 0.1, 2], [0.03, 0.02, 0.02], 80), ([1.5, 0, 2], [0.05, 0.05, 0.05], 100))]
    points = np.concatenate(parts)
    graph = bands.Neighbours.build(points, 0.08)
    dense = bands.density_mask(graph, 6)
    entity = np.where(points[:, 0] < 1.0, 0, 1)
    entity[rng.random(len(points)) < 0.02] = -1
    seeds = np.array([0, 700 + seed])
    out = []
    for enabled in (True, False):
        monkeypatch.setattr(kernels, 'ENABLED', enabled)
        bridges: list[tuple[int, int]] = []
        band = bands.expand_bands(graph, dense, seeds, 0.08, max_bands=max_bands,
                                  points=points, entity=entity, bridge_gap=0.3,
                                  bridges=bridges)
        out.append((band, bridges))
    assert (out[1][0] > 1).sum() > 100 and (out[1][0] == bands.UNREACHED).any()
    np.testing.assert_array_equal(out[0][0], out[1][0])
    assert out[0][1] == out[1][1] and (max_bands or out[1][1])  # bridged, unless cut short


#: A function whose code says it is llvmlite's: where numba's compilation calls back into
#: Python (ctypes callbacks, in which an exception is printed and swallowed).
_FAKE_LLVMLITE = compile('def call(f):\n    return f()\n',
                         os.path.join(os.sep, 'site', 'llvmlite', 'binding', 'fake.py'), 'exec')


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize('in_llvmlite', [False, True])
def test_a_signal_while_a_kernel_compiles(signum, in_llvmlite, monkeypatch):
    """Ctrl-C or SIGTERM during a kernel's first call (numba compiling) ends the command: at
    once, or, when it comes while llvmlite's code runs (where the exception would be
    swallowed), as soon as the compilation is over; never not at all."""
    done = []

    def body() -> int:
        os.kill(os.getpid(), signum)
        time.sleep(0.05)  # the handler runs here
        done.append(True)
        return 7

    scope: dict = {}
    exec(_FAKE_LLVMLITE, scope)  # noqa: S102 - a code object of this file
    compiled = (lambda: lambda: scope['call'](body)) if in_llvmlite else (lambda: body)
    previous = signal.signal(signal.SIGTERM, cli_common.raise_terminated)
    try:
        kernel = kernels._Compiled(body)
        monkeypatch.setattr(kernel, '_compile', compiled)
        with pytest.raises(KeyboardInterrupt):  # Terminated is one too
            kernel()
            time.sleep(0.5)
        assert done == ([True] if in_llvmlite else [])
        assert signal.getsignal(signal.SIGTERM) is cli_common.raise_terminated
    finally:
        signal.signal(signal.SIGTERM, previous)


@compiled
@pytest.mark.parametrize('told', ['all', 'kinds', 'parts'])
@pytest.mark.parametrize('learning', [False, True])
def test_confirm_compiled_equals_numpy(told, learning, monkeypatch):
    """The marks of the entities of the start on random labels, verdicts and states (held,
    parts, counted, flagged, the person's pixels), in both codes from the same state."""
    rng = np.random.default_rng(11)
    shape = (60, 80)
    model = BackgroundModel()
    first = _patchwork(rng, shape)
    model.foreground(first, first > 0, 0, PARAMS)
    model._init_z[:] = np.where(rng.random(shape) < 0.5, first, 0)
    monkeypatch.setattr(BackgroundModel, 'learning', property(lambda _self: learning))
    twin = copy.deepcopy(model)
    for k in range(1, 6):
        labels = rng.integers(0, 8, shape).astype(np.int32)
        verdicts = rng.random((4, 8)) < 0.5
        pixels = rng.random(shape) < 0.5
        outs = []
        for enabled, m in ((True, model), (False, twin)):
            monkeypatch.setattr(kernels, 'ENABLED', enabled)
            m._t = k / 10.0
            parts = verdicts[1] if told == 'parts' else None
            kinds = told != 'all'
            m._confirm(labels, verdicts[0], parts, verdicts[2] if kinds else None,
                       verdicts[3] if kinds else None, None if parts is None else pixels)
            outs.append([m._near_since, m._init_z, m._init_seen, m._init_votes])
        assert outs[1][2].any() == kinds
        for a, b in zip(*outs):
            np.testing.assert_array_equal(a, b, err_msg=f'frame {k}')


def test_a_handler_that_changes_its_signal_keeps_its_change(monkeypatch):
    """A worker's SIGTERM handler raises once and then ignores SIGTERM (the parent sends it
    again): run during a kernel's first call, that stays so after the call, and the second
    SIGTERM cannot break the cleanup of the first."""
    previous = signal.signal(signal.SIGTERM, workers._on_sigterm)

    def body() -> None:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.05)

    try:
        kernel = kernels._Compiled(body)
        monkeypatch.setattr(kernel, '_compile', lambda: body)
        with pytest.raises(KeyboardInterrupt):
            kernel()
        assert signal.getsignal(signal.SIGTERM) == signal.SIG_IGN
    finally:
        signal.signal(signal.SIGTERM, previous)
