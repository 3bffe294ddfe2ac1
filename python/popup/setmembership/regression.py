"""The linear regression of a structure on data (:func:`regressors`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import List

import numpy as np

from ..exceptions import InputError, ParameterError
from .structure import ArrayLike, Structure
from .data import IdData, as_data


# ============================================================== regressors
@dataclass
class Regression:
    """A linear regression ``y = Φ θ + e`` (one row per sample kept).

    Attributes
    ----------
    phi : ndarray (n, p)
    y : ndarray (n,)
    names : list of str
        Parameter names (columns of ``phi``).
    rows : ndarray (n,) of int
        Sample index of every row in the data.
    """

    phi: np.ndarray
    y: np.ndarray
    names: List[str]
    rows: np.ndarray


def shift(x: np.ndarray, lag: int) -> np.ndarray:
    """x(t − lag) with zeros before the start (rest), same length."""
    if lag == 0:
        return x
    out = np.zeros_like(x)
    if lag < x.shape[0]:
        out[lag:] = x[: x.shape[0] - lag]
    return out


def regressors(structure: Structure, y: ArrayLike, u: ArrayLike, *, skip: int = 0) -> Regression:
    """The regression of a FIR or ARX structure: row ``t`` is ``φ(t) = [−y(t−1) … −y(t−na),
    u_j(t−nk_j) … u_j(t−nk_j−nb_j+1) per input, 1]``, for ``t = max_lag + skip … N−1``
    (the first :attr:`Structure.max_lag` samples have no complete past). Built with one
    vectorised slice per column.

    Raises :class:`~popup.InputError` for mismatched lengths, non-finite samples, the wrong
    number of inputs, or fewer usable samples than parameters.
    """
    s = structure
    if s.kind not in ("fir", "arx"):
        raise ParameterError(f"regressors: {s.kind.upper()} is not linear in its parameters; use oe_pui()")
    d = y if isinstance(y, IdData) else as_data(y, u, s.output, s.inputs)
    return build_regression(s, d.y, d.u, skip)


def build_regression(s: Structure, y: np.ndarray, u: np.ndarray, skip: int) -> Regression:
    if isinstance(skip, bool) or not float(skip).is_integer() or skip < 0:
        raise ParameterError(f"skip must be a whole number >= 0, got {skip!r}")
    n_all = y.shape[0]
    t0 = s.max_lag + int(skip)
    n = n_all - t0
    p = s.n_params
    if n < max(p, 1):
        raise InputError(f"too few samples for {s.describe()}: {n_all} given, {t0} lost to the lags/skip, "
                         f"{max(n, 0)} rows left for {p} parameters (need at least {p + t0} samples)")
    phi = np.empty((n, p))
    col = 0
    for i in range(1, s.na + 1):
        phi[:, col] = -y[t0 - i : n_all - i]
        col += 1
    for j in range(s.n_inputs):
        for k in range(s.nb[j]):
            lag = s.nk[j] + k
            phi[:, col] = u[t0 - lag : n_all - lag, j]
            col += 1
    if s.offset:
        phi[:, col] = 1.0
    return Regression(phi, y[t0:].copy(), s.names, np.arange(t0, n_all))
