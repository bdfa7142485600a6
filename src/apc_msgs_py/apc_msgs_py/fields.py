"""The border checks every converter applies: names, lengths, finiteness and bound of a field.

A malformed message is rejected with a :class:`WireError` whose text starts with the field
(``"position: NaN at joint 'j2'"``); an array about to be published is checked the same way,
so garbage is never handed to a controller nor put on the wire.
"""

from __future__ import annotations

import array
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

#: Default bound on ``|value|`` for every numeric field read or written here. Nothing physical in
#: apc comes near it (rad, rad/s, rad/s², N·m of an arm); a value beyond it is a unit mix-up or
#: uninitialised memory, not a state.
DEFAULT_MAX_ABS = 1.0e6


class WireError(ValueError):
    """A message (or an array about to be published) that breaks the wire contract.

    The text starts with the offending field (``"position: NaN at joint 'j2'"``), so a node can
    log it as is. Nodes catch it, count it, log it (throttled) and carry on.
    """


#: Permutations of name lists already checked, (got, names, allow_extra) -> perm: the same few
#: lists arrive every sample, and a dict lookup is a fraction of the check. Bounded.
_PERMS: dict[tuple[tuple[str, ...], tuple[str, ...], bool], list | None] = {}
_MAX_PERMS = 256


def check_names(
    got: Sequence[str], names: Sequence[str], field: str, allow_extra: bool
) -> list | None:
    """Return ``perm`` with ``got[perm[i]] == names[i]`` (``None`` when it is the identity);
    raise WireError naming ``field``."""
    key = (tuple(got), tuple(names), allow_extra)
    try:
        return _PERMS[key]
    except KeyError:
        pass
    perm = _name_permutation(got, names, field, allow_extra)
    if len(_PERMS) >= _MAX_PERMS:
        _PERMS.clear()
    _PERMS[key] = None if perm == list(range(len(got))) else perm
    return _PERMS[key]


def _name_permutation(
    got: Sequence[str], names: Sequence[str], field: str, allow_extra: bool
) -> list:
    if len(got) == 0:
        raise WireError(f"{field}: empty (no joints in the message)")
    index: dict[str, int] = {}
    for i, name in enumerate(got):
        if name in index:
            raise WireError(f"{field}: duplicated joint {name!r}")
        index[name] = i
    missing = [n for n in names if n not in index]
    if missing:
        raise WireError(f"{field}: missing joint(s) {missing}; expected {list(names)}")
    if not allow_extra and len(index) != len(names):
        wanted = set(names)
        unknown = [n for n in got if n not in wanted]
        raise WireError(f"{field}: unknown joint(s) {unknown}; expected {list(names)}")
    return [index[n] for n in names]


_max_reduce = np.maximum.reduce
_min_reduce = np.minimum.reduce


def check_finite(values: np.ndarray, field: str, labels: Sequence[str], max_abs: float) -> None:
    """Raise WireError if ``values`` holds NaN, Inf, or ``|v| > max_abs``; name the joint."""
    # Fast path (this runs ~25 times per sample): the sum of the entries is finite only if none
    # is NaN or Inf (x - x == 0 fails for both), then one bound on the largest |v|. For the short
    # vectors of a joint state plain Python is 3x quicker than numpy's reductions. Only a
    # failure (which includes a sum that merely overflows) gets the entry-by-entry check.
    if values.size <= 32:
        entries = values.ravel().tolist()
        total = sum(entries)
        if total - total == 0.0 and max(map(abs, entries), default=0.0) <= max_abs:
            return
    else:
        flat = values.ravel()
        low, high = _min_reduce(flat), _max_reduce(flat)
        if -max_abs <= low and high <= max_abs and high != math.inf and low != -math.inf:
            return
    finite = np.isfinite(values)
    if not finite.all():
        i = int(np.flatnonzero(~finite.ravel())[0])
        v = values.ravel()[i]
        kind = "NaN" if math.isnan(v) else "Inf"
        raise WireError(f"{field}: {kind} at {_label(labels, i)}")
    if values.size and float(np.max(np.abs(values))) > max_abs:
        i = int(np.argmax(np.abs(values).ravel()))
        raise WireError(
            f"{field}: |{values.ravel()[i]:.6g}| at {_label(labels, i)} exceeds max_abs {max_abs:g}"
        )


def _label(labels: Sequence[str], i: int) -> str:
    """``joint 'j2' (index 1)`` for a per-joint vector, ``index i`` otherwise."""
    if len(labels) > 0:
        return f"joint {labels[i % len(labels)]!r} (index {i})"
    return f"index {i}"


def field_array(
    values: Any,
    perm: list | None,
    n: int,
    field: str,
    required: bool,
    names: Sequence[str],
    max_abs,
) -> np.ndarray | None:
    """Read a float64 sequence field of length n (or 0 if optional), reorder, validate."""
    length = len(values)
    if length == 0 and not required:
        return None
    if length != n:
        what = f"{n} (one per name)" if required else f"0 or {n} (one per name)"
        raise WireError(f"{field}: length {length}, expected {what}")
    if isinstance(values, array.array):
        raw = np.frombuffer(values, dtype=np.float64) if length else np.empty(0)
    else:
        raw = np.asarray(values, dtype=np.float64)
    # A copy either way: the result never aliases the message.
    out = raw.copy() if perm is None else raw[perm]
    check_finite(out, field, names, max_abs)
    return out


def as_vector(values: Any, n: int, field: str, names: Sequence[str], max_abs) -> np.ndarray:
    """Validate an array about to be published: shape (n,), finite, bounded."""
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise WireError(f"{field}: not a float array ({err})") from None
    if arr.shape != (n,):
        raise WireError(f"{field}: shape {arr.shape}, expected ({n},) (one per joint)")
    check_finite(arr, field, names, max_abs)
    return arr


def to_double_array(arr: np.ndarray | None) -> array.array:
    if arr is None:
        return array.array("d")
    return array.array("d", np.ascontiguousarray(arr, dtype=np.float64).tobytes())


def set_names(current: Sequence[str], names: Sequence[str]) -> list[str] | None:
    """Return a new name list if ``current`` differs from ``names`` (avoids re-validation)."""
    wanted = list(names)
    return None if list(current) == wanted else wanted
