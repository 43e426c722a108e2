"""Array validation for the frozen value types: say exactly which field is wrong."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray


def checked_array(
    name: str,
    value: ArrayLike,
    shape: Sequence[int | None],
    dtype: type | np.dtype = np.float64,
    *,
    finite: bool = True,
) -> NDArray:
    """Return ``value`` as a read-only array of ``dtype`` with ``shape``.

    ``None`` in ``shape`` matches any length. Raises ``ValueError`` naming
    ``name`` when the shape is wrong, the values are not finite (for float
    dtypes, when ``finite``), or the conversion fails.
    """
    try:
        arr = np.array(value, dtype=dtype, copy=True)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: cannot convert to {np.dtype(dtype).name} array ({exc})") from None
    if arr.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, arr.shape, strict=True)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {arr.shape}")
    if finite and np.issubdtype(arr.dtype, np.floating) and not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise ValueError(f"{name}: {bad} non-finite value(s) (NaN or inf)")
    arr.setflags(write=False)
    return arr


def check_positive(name: str, value: float, *, allow_zero: bool = False) -> None:
    """Raise ``ValueError`` unless ``value`` is a finite number > 0 (or >= 0)."""
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        op = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name}: must be a finite number {op}, got {value!r}")


def require(cond: bool, msg: str) -> None:
    """Raise ``ValueError(msg)`` unless ``cond``: the one-line check of the config dataclasses."""
    if not cond:
        raise ValueError(msg)


def finite(*values: object) -> bool:
    """Whether every value is a real number (not a bool) and finite."""
    return all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in values)


def integer(value: object) -> bool:
    """Whether ``value`` is an int and not a bool (``True`` is an int to Python, not a count)."""
    return isinstance(value, int) and not isinstance(value, bool)
