"""Progress bars move while work runs: a bar over a few long fits, or a step without a
count of its own, is redrawn with its elapsed time and the evaluations done in it."""

import io
import logging
import threading
import time

import pytest

from sknarx import _progress


@pytest.fixture
def info_level():
    log = logging.getLogger("sknarx")
    old = log.level
    log.setLevel(logging.INFO)
    yield
    log.setLevel(old)


def test_a_phase_is_redrawn_with_its_evaluations_while_it_runs(info_level, monkeypatch):
    monkeypatch.setattr(_progress, "REFRESH_S", 0.05)
    out = io.StringIO()
    monkeypatch.setattr(_progress.sys, "stderr", out)
    stop = threading.Event()

    def work():  # another thread's simulations are counted too
        while not stop.is_set():
            _progress.evaluated()
            time.sleep(0.01)

    worker = threading.Thread(target=work)
    with _progress.phase("nuisance calibration"):
        worker.start()
        time.sleep(0.6)
        stop.set()
        worker.join()
    frames = [f for f in out.getvalue().split("\r") if "nuisance calibration" in f]
    assert len(frames) >= 4, frames  # several redraws, not one at the start and the end
    counts = [int(f.split(", ")[1].split()[0]) for f in frames if "evaluations" in f]
    assert counts and counts == sorted(counts) and counts[-1] > counts[0] > 0
    assert not _progress._open  # closed bars leave the ticker's list


def test_a_bar_over_fits_moves_before_its_first_fit_ends(info_level, monkeypatch):
    monkeypatch.setattr(_progress, "REFRESH_S", 0.05)
    out = io.StringIO()
    monkeypatch.setattr(_progress.sys, "stderr", out)

    def slow_fits():
        for _ in range(2):
            for _ in range(20):
                _progress.evaluated()
                time.sleep(0.01)
            yield None

    list(_progress.progress_bar(slow_fits(), total=2, desc="effect candidates", unit="fit"))
    before_first = [f for f in out.getvalue().split("\r") if "0/2" in f]
    assert len(before_first) >= 2 and any("evaluations" in f for f in before_first)


def test_bars_are_silent_unless_info_is_enabled(monkeypatch):
    log = logging.getLogger("sknarx")
    old = log.level
    log.setLevel(logging.WARNING)
    out = io.StringIO()
    monkeypatch.setattr(_progress.sys, "stderr", out)
    try:
        with _progress.phase("quiet"):
            _progress.evaluated(3)
    finally:
        log.setLevel(old)
    assert out.getvalue() == "" and not _progress._open
