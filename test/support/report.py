"""Measurements a system test prints (shown with ``pytest -s``), for docs/reliability.md to
quote: what the tests assert are the documented bounds, what they measure is printed."""

from __future__ import annotations


def report(what: str, **values: object) -> None:
    """Print a measurement (shown with ``pytest -s``; quoted in docs/reliability.md)."""
    text = ", ".join(
        f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in values.items()
    )
    print(f"\n[faults] {what}: {text}", flush=True)
