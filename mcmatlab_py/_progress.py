"""A small progress bar on stderr, shown only for runs that last more than a few seconds."""

from __future__ import annotations

import sys
import time


class Progress:
    """Progress of a long loop: ``update(done)`` with ``done`` in [0, total].

    Nothing is printed during the first ``delay`` seconds, so short runs stay
    quiet; ``enabled=False`` silences it entirely (``--quiet``).
    """

    def __init__(self, total: float, label: str, *, enabled: bool = True, delay: float = 2.0,
                 stream=None):
        self.total = max(float(total), 1e-300)
        self.label = label
        self.enabled = enabled
        self.delay = delay
        self.stream = stream if stream is not None else sys.stderr
        self.t0 = time.perf_counter()
        self._shown = False
        self._last = 0.0

    def update(self, done: float, extra: str = "") -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        elapsed = now - self.t0
        if elapsed < self.delay or (now - self._last < 0.2 and done < self.total):
            return
        self._last = now
        frac = min(1.0, done / self.total)
        eta = elapsed * (1 - frac) / frac if frac > 0 else float("inf")
        bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
        self.stream.write(
            f"\r{self.label} [{bar}] {100 * frac:5.1f}% {elapsed:6.1f}s elapsed, "
            f"{eta:6.1f}s left {extra}"
        )
        self.stream.flush()
        self._shown = True

    def close(self) -> None:
        if self._shown:
            self.stream.write("\n")
            self.stream.flush()
