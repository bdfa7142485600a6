"""The check at every numeric boundary of the laws: a value is a finite float64 array of exactly
the shape asked for, or the caller's error names what is wrong with it; and the reductions the
per-sample checks use."""

from __future__ import annotations

from typing import Any

import numpy as np


def finite_array(
    name: str, value: Any, shape: tuple[int, ...], error: type[Exception], *, copy: bool = False
) -> np.ndarray:
    """``value`` as a finite float64 array of ``shape`` (a fresh copy with ``copy``, else
    ``value`` itself when it already is one); ``error`` naming ``name`` otherwise."""
    try:
        a = np.array(value, dtype=float) if copy else np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise error(f"{name} must be a real array of shape {shape}") from None
    if a.shape != shape:
        raise error(f"{name} must have shape {shape}, got {a.shape}")
    if not np.isfinite(a).all():
        raise error(f"{name} must be finite")
    return a


#: ``any`` / ``all`` of a boolean array as the bare ufunc reductions: ``np.any`` and
#: ``ndarray.all`` add a Python wrapper that costs more than the reduction at a joint state's
#: size, on checks that run every sample.
any_true = np.logical_or.reduce
all_true = np.logical_and.reduce
