"""Fit an additive logistic model (:class:`endeff_ros.core.additive.AdditiveModel`).

Each feature is cut at the quantiles of the rows (at most ``bins`` intervals; a binary feature
once at 0.5; a sentinel value such as "no floor known" in an interval of its own), and the
weights are found by Newton's method with a penalty on the differences of neighbouring
intervals' weights (each feature's effect is smooth unless many rows say otherwise) and a
small one on the weights (the fit stays defined where a feature is constant).
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np

from endeff_ros.core.additive import AdditiveModel

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
    for _ in range(iterations):
        z = b + x @ w
        p = 1.0 / (1.0 + np.exp(-z))
        r = sw * p * (1 - p)
        g_w = x.T @ (sw * (p - y)) + reg @ w
        g_b = float(np.sum(sw * (p - y)))
        xr = x * r[:, None].astype(np.float32)
        h_ww = x.T @ xr + reg
        h_wb = xr.sum(axis=0)
        h = np.block([[h_ww, h_wb[:, None]], [h_wb[None, :], np.array([[r.sum()]])]])
        step = np.linalg.solve(h, np.r_[g_w, g_b])
        w -= step[:-1]
        b -= float(step[-1])
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
