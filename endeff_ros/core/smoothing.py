"""One Euro filter of the published end-effector positions, and their velocity.

A detection moves with the part it follows but also with the noise of a single frame: which
sub-band is the part's end, how many of its points the sensor read. Differentiated, that noise
swamps the velocity. The One Euro filter (Casiez, Roussel & Vogel, *1€ Filter: A Simple
Speed-based Low-pass Filter for Noisy Input in Interactive Systems*, CHI 2012) low-passes each
position with a cutoff that rises with its speed: a still hand is smoothed hard (its cutoff
``min_cutoff``), a fast one hardly at all (``min_cutoff + beta |velocity|``), so the lag stays
small where it would show. Parameters as the paper names them: ``min_cutoff`` (Hz), ``beta``
(s/m), ``d_cutoff`` (Hz, the cutoff of the velocity estimate that drives the adaptation).

Lag: at a steady velocity v a first-order low-pass trails by v τ, τ = 1 / (2π f_c); with
f_c = min_cutoff + beta |v| that is v / (2π (min_cutoff + beta |v|)), which approaches
1 / (2π beta) as v grows (1.6 cm for beta = 10 s/m: a 2 m/s hand trails by 1.5 cm). It is
also bounded outright: a filtered position farther than ``max_lag`` from its raw one is pulled
back to that distance. A raw step longer than ``reset_distance`` between two frames is the
track moving to another point (a case-B end replaced by its candidate, a reacquired end), not
motion: the filter starts again there, velocity zero.

Vectorised over the tracks of a frame; the state lives with each track (the tracker keeps it).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

if TYPE_CHECKING:
    import numpy.typing as npt


class OneEuroParams(NamedTuple):
    """The filter's parameters (the paper's names), in Hz, s/m, Hz, m, m."""

    min_cutoff: float
    beta: float
    d_cutoff: float
    max_lag: float = 0.0  # 0: unbounded
    reset_distance: float = 0.0  # 0: never restart


def smoothing_factor(cutoff: npt.ArrayLike, dt: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """α of an exponential low-pass with ``cutoff`` (Hz) sampled every ``dt`` s:
    1 / (1 + τ / dt), τ = 1 / (2π cutoff)."""
    tau = 1.0 / (2.0 * np.pi * np.asarray(cutoff, dtype=np.float64))
    return 1.0 / (1.0 + tau / np.asarray(dt, dtype=np.float64))


def one_euro(raw: npt.ArrayLike, raw_previous: npt.ArrayLike, previous: npt.ArrayLike,
             velocity: npt.ArrayLike, dt: npt.ArrayLike, params: OneEuroParams,
             ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """One step for N points: (N, 3) ``raw`` positions, the (N, 3) raw and filtered
    positions and the ``velocity`` (m/s) of the step before (``raw_previous``, ``previous``),
    ``dt`` (s, scalar or (N,)) since then. Returns the filtered positions and velocities.

    The velocity is the low-passed (``d_cutoff``) difference of the raw positions, as in the
    authors' reference code: the difference to the filtered position would add the lag over
    ``dt`` to it (0.45 m/s for a 1.5 cm lag at 30 Hz)."""
    x = np.asarray(raw, dtype=np.float64).reshape(-1, 3)
    x_prev = np.asarray(raw_previous, dtype=np.float64).reshape(-1, 3)
    prev = np.asarray(previous, dtype=np.float64).reshape(-1, 3)
    v_prev = np.asarray(velocity, dtype=np.float64).reshape(-1, 3)
    dt = np.maximum(np.broadcast_to(np.asarray(dt, dtype=np.float64), (len(x),)), 1e-4)[:, None]
    a_d = smoothing_factor(params.d_cutoff, dt)
    v = a_d * (x - x_prev) / dt + (1.0 - a_d) * v_prev
    cutoff = params.min_cutoff + params.beta * np.linalg.norm(v, axis=1, keepdims=True)
    a = smoothing_factor(cutoff, dt)
    out = a * x + (1.0 - a) * prev
    if params.max_lag > 0:
        lag = out - x
        norm = np.linalg.norm(lag, axis=1, keepdims=True)
        over = norm > params.max_lag
        out = np.where(over, x + lag * (params.max_lag / np.maximum(norm, 1e-12)), out)
    if params.reset_distance > 0:
        jumped = np.linalg.norm(x - x_prev, axis=1, keepdims=True) > params.reset_distance
        out = np.where(jumped, x, out)
        v = np.where(jumped, 0.0, v)
    return out, v
