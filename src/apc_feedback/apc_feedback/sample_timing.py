"""Robot mode's timing figures per sample, for ``/diagnostics``: a state's age, its stamp to its
command's publish, the samples' phase, how far states are carried and the driver's period,
each as median, p99 and max over the last samples (plain classes, no rclpy)."""

from __future__ import annotations

import math
from collections import deque

from apc_feedback.robot_sampling import Take


class TimingWindow:
    """The last ``size`` values of one figure (ns); median, p99 and max over them.

    p99 is the nearest-rank percentile: a value that occurred, the smallest one that at least
    99 % of the window does not exceed.
    """

    def __init__(self, size: int) -> None:
        self._values: deque[int] = deque(maxlen=size)

    def __len__(self) -> int:
        return len(self._values)

    def add(self, value_ns: int) -> None:
        self._values.append(int(value_ns))

    def figures(self) -> tuple[float, float, float]:
        """(median, p99, max) in ns; the window must hold a value."""
        ordered = sorted(self._values)
        n = len(ordered)
        median = 0.5 * (ordered[(n - 1) // 2] + ordered[n // 2])
        return median, float(ordered[math.ceil(0.99 * n) - 1]), float(ordered[-1])


class SampleTiming:
    """Robot mode's timing per sample, over the last ``window`` samples (for ``/diagnostics``).

    - ``state_age``: the state's age when its callback ran (its trip from the driver);
    - ``state_to_command``: the state's stamp to its command's publish (the trip, the wait for
      a late set point, the law);
    - ``sample_phase``: the samples' phase within ``T`` (fixed between starts);
    - ``carry``: how far the state was carried to its sample's time, ``|offset|`` (0 when the
      driver's period divides ``T``);
    - ``driver_period``: the driver's period estimated from its stamps when the sample was
      taken.

    :meth:`figures` gives each as ``<name>_median_us``, ``<name>_p99_us``, ``<name>_max_us``.
    """

    NAMES = ("state_age", "state_to_command", "sample_phase", "carry", "driver_period")

    def __init__(self, window: int = 1000) -> None:
        self.windows = {name: TimingWindow(window) for name in self.NAMES}

    def sampled(self, take: Take, phase_ns: int, driver_period_ns: int) -> None:
        """A sample was taken (``take``), with the sampler's phase and driver period then."""
        windows = self.windows
        windows["state_age"].add(take.age_ns)
        windows["sample_phase"].add(phase_ns)
        windows["carry"].add(abs(take.offset_ns))
        windows["driver_period"].add(driver_period_ns)

    def commanded(self, state_ns: int, published_ns: int) -> None:
        """The command computed from the state stamped ``state_ns`` went out at ``published``."""
        self.windows["state_to_command"].add(published_ns - state_ns)

    def figures(self) -> dict[str, float]:
        """Every figure with values, in microseconds."""
        out: dict[str, float] = {}
        for name, window in self.windows.items():
            if len(window):
                median, p99, largest = window.figures()
                out[f"{name}_median_us"] = median * 1e-3
                out[f"{name}_p99_us"] = p99 * 1e-3
                out[f"{name}_max_us"] = largest * 1e-3
        return out
