"""Inverses and log-determinants of stacks of small matrices, without ``numpy.linalg``'s per-call overhead.

The EM and MVEE loops (``planner.mixture``, ``planner.bic_search``, ``planner.mvee``) invert stacks of 3x3
and 4x4 matrices thousands of times a plan, where ``numpy.linalg.inv`` and ``slogdet`` spend more time on
type checks than on LAPACK. These call the same LAPACK kernels (numpy's ``_umath_linalg`` gufuncs, which
``numpy.linalg`` calls), so results are bit-identical (``tests/planner/test_small_linalg.py``); a singular
matrix (a non-finite inverse) goes to ``numpy.linalg.inv``, which raises ``LinAlgError`` as before.
"""

from __future__ import annotations

import math
from typing import cast

import numpy as np
from numpy.typing import NDArray

try:
    from numpy.linalg import _umath_linalg  # private: present in numpy 1.x and 2.x

    _INV, _SLOGDET = _umath_linalg.inv, _umath_linalg.slogdet
except (ImportError, AttributeError):  # pragma: no cover - another numpy: the public functions
    _INV = _SLOGDET = None


def inv(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """(..., n, n) float64 -> (..., n, n): ``numpy.linalg.inv(a)``, bit for bit."""
    if _INV is None or a.dtype != np.float64:
        return cast("NDArray[np.float64]", np.linalg.inv(a))  # (another dtype keeps its own)
    with np.errstate(invalid="ignore"):  # a singular matrix sets "invalid": numpy.linalg reports it below
        out = _INV(a, signature="d->d")
    if not math.isfinite(out.sum()):  # singular (NaN), or entries that overflow: numpy.linalg decides
        return cast("NDArray[np.float64]", np.linalg.inv(a))
    return out


def logdet(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """(..., n, n) float64 -> (...,): ``numpy.linalg.slogdet(a)[1]`` (log |det a|), bit for bit."""
    if _SLOGDET is None or a.dtype != np.float64:
        return np.linalg.slogdet(a)[1]
    return _SLOGDET(a, signature="d->dd")[1]
