"""Progress bars for long phases, shown when the ``sknarx`` logger reports INFO.

The command line sets that level (``--quiet`` lowers it); a library user opts in with
``logging.basicConfig(level=logging.INFO)`` or
``logging.getLogger("sknarx").setLevel(logging.INFO)``. Bars go to stderr, so
output files and piped stdout stay clean.

A bar over a few long fits would sit still for minutes, so every open bar is redrawn
each :data:`REFRESH_S` seconds by one background thread, with its elapsed time and the
number of model evaluations (simulations) done since it opened: the numerical code
calls :func:`evaluated` for each, from whatever thread it runs on. Work in other
processes (a process or dask backend) is not counted; the elapsed time still moves.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
import time

from tqdm.auto import tqdm

__all__ = ["progress_bar", "phase", "evaluated", "evaluations", "REFRESH_S"]

#: seconds between redraws of an open bar (the elapsed time and evaluation count move)
REFRESH_S = 2.0

_lock = threading.Lock()
_count = 0
_open: list = []
_ticker: threading.Thread | None = None


def evaluated(n: int = 1) -> None:
    """Count ``n`` model evaluations (a simulated speed step, a response curve)."""
    global _count
    with _lock:
        _count += n


def evaluations() -> int:
    """Model evaluations counted so far in this process."""
    with _lock:
        return _count


def _enabled() -> bool:
    return logging.getLogger("sknarx").isEnabledFor(logging.INFO)


class _Bar(tqdm):
    """A tqdm bar that the ticker redraws with its evaluation count while open."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._first = evaluations()
        if not self.disable:
            _register(self)

    def close(self):
        with _lock:
            if self in _open:
                _open.remove(self)
        super().close()

    def _tick(self):
        n = evaluations() - self._first
        if n:
            self.set_postfix_str(f"{n} evaluations", refresh=False)
        self.refresh()


def _register(bar) -> None:
    global _ticker
    with _lock:
        _open.append(bar)
        if _ticker is None or not _ticker.is_alive():
            _ticker = threading.Thread(target=_tick_loop, name="sknarx-progress",
                                       daemon=True)
            _ticker.start()


def _tick_loop() -> None:
    """Redraw every open bar each :data:`REFRESH_S` s, for the life of the process (a
    daemon thread: it never keeps the interpreter from exiting)."""
    while True:
        time.sleep(REFRESH_S)
        with _lock:
            bars = list(_open)
        for bar in bars:
            with contextlib.suppress(Exception):  # a bar closed meanwhile
                bar._tick()


def progress_bar(iterable=None, total=None, desc=None, unit="it"):
    """A tqdm bar (with an ETA) over ``iterable``, silent unless INFO is enabled; redrawn
    every :data:`REFRESH_S` s with the evaluations done while it is open."""
    return _Bar(iterable, total=total, desc=desc, unit=unit, disable=not _enabled(),
                file=sys.stderr, dynamic_ncols=True, leave=False)


@contextlib.contextmanager
def phase(desc: str):
    """A bar for one long step without a count of its own (a calibration, an update):
    its elapsed time and the evaluations done in it, redrawn every :data:`REFRESH_S`
    s."""
    bar = _Bar(total=None, desc=desc, unit="", disable=not _enabled(), file=sys.stderr,
               dynamic_ncols=True, leave=False,
               bar_format="{desc}: {elapsed}{postfix}")
    try:
        yield bar
    finally:
        bar.close()
