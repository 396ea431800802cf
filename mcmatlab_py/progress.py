"""Progress bars for long runs, through tqdm (terminals, notebooks, and logs alike).

tqdm writes carriage-return frames only to a terminal; into a log or a CI transcript
it writes a few plain lines (``mininterval`` is raised there). Nothing is shown for
runs shorter than ``delay`` seconds, and ``enabled=False`` (``--quiet``) hides the bar
only: results are printed by the callers, never through here.
"""

from __future__ import annotations

import sys

from tqdm.auto import tqdm

__all__ = ["Progress"]


class _Lines:
    """A log or a pipe: each tqdm frame on a line of its own instead of ``\r`` overwrites."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text: str) -> None:
        for frame in text.split("\r"):
            if frame.strip():
                self.stream.write(frame.rstrip("\n") + "\n")

    def flush(self) -> None:
        self.stream.flush()


class Progress:
    """Progress of a long loop: ``update(done)`` with ``done`` in [0, total].

    Parameters
    ----------
    total : float
        The value of ``done`` at the end (a count, or seconds for a timed run).
    label : str
        Shown before the bar.
    enabled : bool
        False hides the bar entirely.
    delay : float
        s: nothing is shown before this much time has passed (short runs stay quiet).
    stream : file, optional
        Where to write (default ``sys.stderr``).
    """

    def __init__(self, total: float, label: str, *, enabled: bool = True, delay: float = 2.0,
                 stream=None):
        stream = stream if stream is not None else sys.stderr
        interactive = bool(getattr(stream, "isatty", lambda: False)())
        self.total = max(float(total), 1e-300)
        self._bar = tqdm(total=float(total), desc=label, disable=not enabled, delay=delay,
                         file=stream if interactive else _Lines(stream),
                         leave=not interactive, dynamic_ncols=True,
                         mininterval=0.2 if interactive else 10.0,
                         bar_format="{desc}: {percentage:5.1f}%|{bar:30}| {elapsed}<{remaining}"
                                    " {postfix}")

    def update(self, done: float, extra: str = "") -> None:
        """Set the position to ``done`` (absolute, not an increment); ``extra`` goes after."""
        bar = self._bar
        if bar.disable:
            return
        if extra:
            bar.set_postfix_str(extra, refresh=False)
        bar.update(min(float(done), bar.total) - bar.n)  # tqdm takes increments

    def close(self) -> None:
        self._bar.close()
