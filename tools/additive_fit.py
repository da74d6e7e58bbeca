"""Fit an additive logistic model (:class:`endeff_ros.core.additive.AdditiveModel`).

Each feature is cut at the quantiles of the rows (at most ``bins`` intervals; a binary feature
once at 0.5; a sentinel value such as "no floor known" in an interval of its own), and the
weights are found by Newton's method with a penalty on the differences of neighbouring
intervals' weights (each feature's effect is smooth unless many rows say otherwise) and a
small one on the weights (the fit stays defined where a feature is constant).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import zlib
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from endeff_ros.bag.reader import bag_name, find_bags
from endeff_ros.cli_common import positive_int
from endeff_ros.core.additive import AdditiveModel
from tools.per_bag import run_per_bag

M = TypeVar('M', bound=AdditiveModel)


def bin_edges(features: np.ndarray, columns: tuple[str, ...], *, bins: int,
              binary: tuple[str, ...] = (), sentinels: dict[str, float] | None = None,
              ) -> list[np.ndarray]:
    """Per feature its interior cuts: 0.5 for a ``binary`` one, else the distinct quantiles
    (a feature of ``sentinels`` keeps its sentinel value, below every other, apart)."""
    edges = []
    for k, name in enumerate(columns):
        if name in binary:
            edges.append(np.array([0.5]))
            continue
        q = np.quantile(features[:, k], np.linspace(0, 1, bins + 1)[1:-1])
        if sentinels and name in sentinels:
            cut = sentinels[name] + 0.5
            q = np.r_[cut, q[q > cut]]
        edges.append(np.unique(q))
    return edges


def design(features: np.ndarray, edges: list[np.ndarray]) -> tuple[np.ndarray, list[int]]:
    """One-hot interval indicators of every feature, (M, sum of intervals), float32."""
    cols, offsets, start = [], [], 0
    for k, e in enumerate(edges):
        b = np.searchsorted(e, features[:, k], side='right')
        one = np.zeros((len(features), len(e) + 1), dtype=np.float32)
        one[np.arange(len(features)), b] = 1.0
        cols.append(one)
        offsets.append(start)
        start += len(e) + 1
    return np.concatenate(cols, axis=1), offsets


def fit(cls: type[M], features: np.ndarray, target: np.ndarray, *, bins: int,
        penalty: float, ridge: float, binary: tuple[str, ...] = (),
        sentinels: dict[str, float] | None = None, weight: np.ndarray | None = None,
        iterations: int = 30) -> M:
    """A ``cls`` model of (M, F) ``features`` (columns ``cls.COLUMNS``) predicting the (M,)
    boolean ``target``; ``weight``: per row its weight in the likelihood (None: 1)."""
    edges = bin_edges(features, cls.COLUMNS, bins=bins, binary=binary, sentinels=sentinels)
    x, offsets = design(features, edges)
    y = target.astype(np.float64)
    sw = np.ones(len(y)) if weight is None else np.asarray(weight, dtype=np.float64)
    w = np.zeros(x.shape[1])
    reg = ridge * np.eye(len(w))
    for o, e in zip(offsets, edges, strict=True):
        d = np.diff(np.eye(len(e) + 1), axis=0)
        reg[o:o + len(e) + 1, o:o + len(e) + 1] += penalty * d.T @ d
    prior = min(max(np.average(y, weights=sw), 1e-3), 1 - 1e-3)
    b = float(np.log(prior / (1 - prior)))

    def loss(w: np.ndarray, b: float) -> tuple[float, np.ndarray]:
        """The penalised negative log-likelihood that Newton's steps descend, and the
        linear predictor it was computed from."""
        z = b + x @ w
        return float(np.sum(sw * (np.logaddexp(0.0, z) - y * z)) + 0.5 * w @ reg @ w), z

    current, z = loss(w, b)
    for _ in range(iterations):
        p = 0.5 * (1.0 + np.tanh(0.5 * z))  # the logistic, without exp's overflow
        r = sw * p * (1 - p)
        g_w = x.T @ (sw * (p - y)) + reg @ w
        g_b = float(np.sum(sw * (p - y)))
        xr = x * r[:, None].astype(np.float32)
        h_ww = x.T @ xr + reg
        h_wb = xr.sum(axis=0)
        h = np.block([[h_ww, h_wb[:, None]], [h_wb[None, :], np.array([[r.sum()]])]])
        step = np.linalg.lstsq(h, np.r_[g_w, g_b], rcond=None)[0]
        # A full Newton step can overshoot far from the optimum (rows then saturate and the
        # Hessian turns singular): halve it until the loss falls.
        for _ in range(30):
            trial, z = loss(w - step[:-1], b - float(step[-1]))
            if trial <= current:
                break
            step = step / 2
        w -= step[:-1]
        b -= float(step[-1])
        current = trial
        if np.max(np.abs(step)) < 1e-6:
            break
    # Each feature's intervals cover every row, so a constant moves freely between a
    # feature's weights and the bias: centre each feature's weights on its mean over the rows
    # (the model's output is unchanged; a weight then reads as that interval's effect).
    weights = []
    for o, e in zip(offsets, edges, strict=True):
        block = w[o:o + len(e) + 1]
        mean = float(np.average(x[:, o:o + len(e) + 1] @ block, weights=sw))
        weights.append(block - mean)
        b += mean
    return cls(cls.COLUMNS, tuple(edges), tuple(weights), b)


# -- the command line of the two-step fitting tools (tools.train_confidence, train_kinds) ----

def steps_parser(doc: str, model_file: Path, what: str) -> tuple[argparse.ArgumentParser,
                                                                   argparse.ArgumentParser]:
    """The ``collect`` / ``fit`` / ``score`` command line of a fitting tool (``doc``: its
    docstring; ``model_file``: the committed model, the default output and input; ``what``:
    what the model is, for the help); returns the parser and the ``fit`` step's, for the
    tool's own options."""
    parser = argparse.ArgumentParser(description=doc.split('\n')[0])
    sub = parser.add_subparsers(dest='step', required=True)
    c = sub.add_parser('collect', help="run the tracker over bags, keep each end's evidence")
    c.add_argument('bags', nargs='+')
    c.add_argument('--out', required=True)
    c.add_argument('--jobs', type=positive_int, default=1)
    f = sub.add_parser('fit', help=f'fit the {what} on collected bags')
    f.add_argument('dirs', nargs='+')
    f.add_argument('--model', default=str(model_file))
    f.add_argument('--json', help='also write the report here')
    f.add_argument('--holdout', action='store_true',
                   help='fit on half the clips, report on the other half (both ways); '
                        'writes no model')
    r = sub.add_parser('score', help=f'report the {what} on collected bags (not their own)')
    r.add_argument('dirs', nargs='+')
    r.add_argument('--model', default=str(model_file))
    r.add_argument('--json', help='also write the report here')
    return parser, f


def collect(collect_bag: Callable[..., str], args: argparse.Namespace) -> int:
    """The ``collect`` step: ``collect_bag(bag, params, out=DIR)`` over every bag of
    ``args.bags`` (in ``args.jobs`` processes), the names written listed on stderr."""
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    names = run_per_bag(partial(collect_bag, out=out), sorted(find_bags(args.bags)), None,
                        args.jobs)
    print('\n'.join(names), file=sys.stderr)
    return 0


def collected_name(bag: Path) -> str:
    """The name of ``bag``'s collected file (no suffix): the bag's name and a hash of its path,
    so that bags of the same name from different folders (suites drawn with other seeds) do
    not overwrite each other."""
    return f'{bag_name(bag)}-{hashlib.sha1(str(bag.resolve()).encode()).hexdigest()[:8]}'


def collected_files(dirs: list[Path]) -> list[Path]:
    """The collected files (``.npz``) in ``dirs`` (folders, or files named directly), sorted;
    exits naming the folders when there are none."""
    files = sorted(f for d in dirs for f in (d.glob('*.npz') if d.is_dir() else [d]))
    if not files:
        msg = f'no collected bags (.npz) in {", ".join(map(str, dirs))}'
        raise SystemExit(msg)
    return files


def holdout_fold(name: str) -> int:
    """The half (0 or 1) of ``--holdout`` that a collected bag falls in: by its clip (the
    name's middle part; the name without its hash for other bags), so that no clip is both
    fitted and reported on."""
    parts = name.split('__')
    clip = parts[1] if len(parts) > 2 else name.rsplit('-', 1)[0]
    return zlib.crc32(clip.encode()) % 2


def holdout_report(bags: list[dict[str, Any]], fit: Callable[[list[dict[str, Any]]], Any],
                   report: Callable[[list[dict[str, Any]], Any], dict[str, Any]],
                   ) -> dict[str, Any]:
    """``--holdout``: per half of the clips (:func:`holdout_fold` of each bag's ``name``), the
    ``report`` on its bags of the model that ``fit`` made of the other half's."""
    fold = [holdout_fold(b['name']) for b in bags]
    return {'folds': [{'held_out_fold': k, **report(
        [b for b, f in zip(bags, fold, strict=True) if f == k],
        fit([b for b, f in zip(bags, fold, strict=True) if f != k]))} for k in (0, 1)]}


def write_model(model: Any, path: str) -> None:
    """Write ``model`` (its ``to_json``) to ``path``."""
    Path(path).write_text(json.dumps(model.to_json(), indent=1) + '\n', encoding='utf-8')


def print_report(result: dict[str, Any], out: str | None) -> None:
    """Print the report, and write it to ``out`` too when given."""
    text = json.dumps(result, indent=1)
    print(text)
    if out:
        Path(out).write_text(text + '\n', encoding='utf-8')
