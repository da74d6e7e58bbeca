"""The static background's cost against another checkout's, call for call, in one process.

On a shared machine whose speed drifts by up to 2x between runs, two benchmark runs cannot
tell a 10 % change. This tool records every call the tracker makes on its
:class:`~endeff_ros.core.background.BackgroundModel` over a synthetic sequence (``foreground``,
``observe_color``, ``protect``, ``mark``), then replays them on a model of this checkout and
one of ``OTHER`` (its ``endeff_ros/core/background.py``, loaded beside this one) in turn, the
order swapped every repetition, and times each ``foreground``. Both must return the same
masks (a change that must not change behaviour); the report gives each one's median and the
ratio of the medians.

    python -m tools.ab_background OTHER_CHECKOUT [--sequence NAME] [--repeats N] [--quick]
                                 [--no-pin] [--json OUT]
"""

from __future__ import annotations

import argparse
import copy
import importlib.util
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from endeff_ros.cli_common import print_json
from endeff_ros.core import background
from tools.bench import _pin_one_core

#: The model's methods that change its state, replayed in the order the tracker called them.
METHODS = ('foreground', 'observe_color', 'protect', 'mark')


def record_calls(sequence: str, *, quick: bool = False,
                 ) -> list[tuple[str, tuple[Any, ...], dict[str, Any]]]:
    """Every call of :data:`METHODS` the tracker makes over ``sequence`` (its ``quick``
    render with ``quick``; arguments copied)."""
    from endeff_ros.core.params import EndeffParams
    from endeff_ros.core.tracker import Tracker
    from endeff_ros.core.types import RGBDFrame
    from endeff_ros.synth import render_sequence

    calls: list[tuple[str, tuple[Any, ...], dict[str, Any]]] = []
    cls = background.BackgroundModel
    originals = {name: getattr(cls, name) for name in METHODS}

    def recorder(name: str, method: Any) -> Any:
        def record(self: Any, *args: Any, **kwargs: Any) -> Any:
            calls.append((name, copy.deepcopy(args), copy.deepcopy(kwargs)))
            return method(self, *args, **kwargs)
        return record

    try:
        for name, method in originals.items():
            setattr(cls, name, recorder(name, method))
        tracker = Tracker(EndeffParams())
        for f in render_sequence(sequence, quick=quick):
            if f.depth is not None:
                tracker.update(RGBDFrame(f.stamp_ns, f.frame_id, f.depth, f.intrinsics, f.color))
    finally:
        for name, method in originals.items():
            setattr(cls, name, method)
    return calls


def other_model(checkout: Path) -> type:
    """``BackgroundModel`` of the checkout at ``checkout`` (its module loaded under another
    name, importing this package's other modules)."""
    path = checkout / 'endeff_ros' / 'core' / 'background.py'
    spec = importlib.util.spec_from_file_location('endeff_ros.core._background_other', path)
    if spec is None or spec.loader is None:
        msg = f'{path}: no background module there'
        raise SystemExit(msg)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.BackgroundModel


def compare(calls: list[tuple[str, tuple[Any, ...], dict[str, Any]]], other: type,
            repeats: int = 5) -> dict[str, Any]:
    """Replay ``calls`` on this checkout's model and ``other``'s in turn ``repeats`` times;
    the first repetition warms up and is not timed. Raises AssertionError where their
    ``foreground`` masks differ. ``foreground_ms`` and ``ratio``: the medians of its calls;
    ``marks_ms``: of the ``protect`` and ``mark`` calls (the tracks' marks)."""
    times: dict[str, dict[str, list[float]]] = {
        group: {'this': [], 'other': []} for group in ('foreground', 'marks')}
    for rep in range(repeats):
        models = {'this': background.BackgroundModel(), 'other': other()}
        order = ('this', 'other') if rep % 2 == 0 else ('other', 'this')
        for call, (name, args, kwargs) in enumerate(calls):
            out = {}
            group = 'marks' if name in ('protect', 'mark') else name
            for key in order:
                t0 = time.perf_counter()
                out[key] = getattr(models[key], name)(*args, **kwargs)
                if group in times and rep:
                    times[group][key].append(time.perf_counter() - t0)
            if name == 'foreground' and not np.array_equal(out['this'], out['other']):
                msg = f'call {call}: the two foreground masks differ'
                raise AssertionError(msg)
    median = {group: {k: float(np.median(v)) * 1e3 if v else 0.0 for k, v in by.items()}
              for group, by in times.items()}
    fg = median['foreground']
    return {'foreground_ms': {k: round(v, 3) for k, v in fg.items()},
            'marks_ms': {k: round(v, 3) for k, v in median['marks'].items()},
            'calls': len(calls), 'timed': len(times['foreground']['this']),
            'ratio': round(fg['this'] / fg['other'], 3)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('other', type=Path, help='the other checkout (a git worktree)')
    parser.add_argument('--sequence', default='waving_two_hands')
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--quick', action='store_true', help="the sequence's quick render")
    parser.add_argument('--no-pin', action='store_true', help='do not pin to one CPU core')
    parser.add_argument('--json')
    args = parser.parse_args(argv)
    if not args.no_pin:
        _pin_one_core()
    calls = record_calls(args.sequence, quick=args.quick)
    report = compare(calls, other_model(args.other), args.repeats)
    print_json({'sequence': args.sequence, **report}, args.json)
    return 0


if __name__ == '__main__':
    sys.exit(main())
