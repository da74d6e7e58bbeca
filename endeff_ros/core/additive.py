"""Additive logistic models over binned features: the published confidence's and the kinds'.

Each feature is cut at fixed edges (quantiles of the training rows), with one weight per
interval, and ``p = 1 / (1 + exp(-(b + sum_f w_f[bin])))``. Additive over binned features, such
a model learns a non-monotone effect per feature; fitted by maximum likelihood, its
probabilities match the observed frequencies of its training rows; a few hundred numbers in a
JSON file, evaluated with numpy (``tools/additive_fit.py`` fits them).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, TypeVar

import numpy as np
import numpy.typing as npt

T = TypeVar('T')


@dataclass(frozen=True)
class AdditiveModel:
    """Additive logistic model over the columns of a feature matrix (see the module). A
    subclass names its matrix's columns (:attr:`COLUMNS`) and what it scores (:attr:`WHAT`,
    for errors)."""

    COLUMNS: ClassVar[tuple[str, ...]] = ()
    WHAT: ClassVar[str] = 'additive'

    names: tuple[str, ...]
    edges: tuple[npt.NDArray[np.float64], ...]  # per feature, its interior bin edges
    weights: tuple[npt.NDArray[np.float64], ...]  # per feature, len(edges) + 1 weights
    bias: float

    def logit(self, features: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """The model's log-odds of (M, F) ``features`` (columns in :attr:`COLUMNS` order)."""
        z = np.full(len(features), self.bias)
        for name, edges, weights in zip(self.names, self.edges, self.weights, strict=True):
            column = features[:, self.COLUMNS.index(name)]
            z += weights[np.searchsorted(edges, column, side='right')]
        return z

    def __call__(self, features: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Probability in [0, 1] per row of ``features``."""
        return 1.0 / (1.0 + np.exp(-self.logit(features)))

    def to_json(self) -> dict[str, Any]:
        """The model's content in its file."""
        return {'bias': self.bias,
                'features': [{'name': n, 'edges': e.tolist(), 'weights': w.tolist()}
                             for n, e, w in zip(self.names, self.edges, self.weights,
                                                strict=True)]}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Any:
        """A model from :meth:`to_json`'s form; raises ValueError on a malformed one."""
        try:
            feats = data['features']
            names = tuple(str(f['name']) for f in feats)
            edges = tuple(np.asarray(f['edges'], dtype=np.float64) for f in feats)
            weights = tuple(np.asarray(f['weights'], dtype=np.float64) for f in feats)
            bias = float(data['bias'])
        except (KeyError, TypeError) as err:
            msg = f'{cls.WHAT} model: missing or malformed field ({err})'
            raise ValueError(msg) from err
        unknown = sorted(set(names) - set(cls.COLUMNS))
        if unknown:
            msg = f'{cls.WHAT} model: unknown features {unknown}'
            raise ValueError(msg)
        for n, e, w in zip(names, edges, weights, strict=True):
            if len(w) != len(e) + 1 or np.any(np.diff(e) < 0):
                msg = f'{cls.WHAT} model: feature {n} has {len(e)} edges and {len(w)} weights'
                raise ValueError(msg)
        return cls(names, edges, weights, bias)


def read_model(path: str | Path, build: Callable[[Any], T]) -> T:
    """The model ``build`` makes of the JSON content of ``path``; raises ValueError naming
    the file when it cannot be read or is malformed (a field missing or of the wrong type)."""
    try:
        return build(json.loads(Path(path).read_text(encoding='utf-8')))
    except (OSError, ValueError, KeyError, TypeError) as err:
        msg = f'{path}: {err}'
        raise ValueError(msg) from err
