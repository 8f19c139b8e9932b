"""A stopped diagnosis resumes from its checkpoint and gives the uninterrupted result."""

import json
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import sknarx.gap.sweep_front as F
import sknarx.gap.timeseries as D
from sknarx._checkpoint import Checkpoint, fingerprint
from sknarx.gap import SearchBudget, diagnose
from sknarx.io import json_safe
from sknarx.testing import make_trial

SPEEDS = tuple(np.linspace(81.7, 276.5, 6).round(4))
FAST = SearchBudget(n_probe=8, max_nfev=8)
CALIBRATE = D.calibrate


def _patch(monkeypatch, calibrate):
    """Every calibration of a diagnosis (the nuisance fit's and the candidates')."""
    monkeypatch.setattr(D, "calibrate", calibrate)
    monkeypatch.setattr(F, "calibrate", calibrate)


class _Stopped(Exception):
    """Stands for Ctrl-C or a killed job in the middle of the search."""


def _counting(stop_after=None):
    calls = []

    def calibrate(*args, **kw):
        if stop_after is not None and len(calls) >= stop_after:
            raise _Stopped
        calls.append(kw.get("n_probe"))
        return CALIBRATE(*args, **kw)

    return calibrate, calls


def _document(result):
    return json.dumps(json_safe(dict(result)), sort_keys=True)


@pytest.fixture(scope="module")
def runout_sweep():
    measured, _ = make_trial("runout", 5, speeds=SPEEDS, n_samples=1000)
    return measured


@pytest.mark.slow
def test_a_stopped_diagnosis_resumes_and_gives_the_uninterrupted_result(
        runout_sweep, tmp_path, monkeypatch):
    kw = {"candidates": ("runout", "crack"), "budget": FAST}
    counting, plain_calls = _counting()
    _patch(monkeypatch, counting)
    plain = diagnose(runout_sweep, **kw)

    stopping, done_before = _counting(stop_after=3)
    _patch(monkeypatch, stopping)
    with pytest.raises(_Stopped):
        diagnose(runout_sweep, checkpoint=tmp_path / "kept", **kw)
    assert len(done_before) == 3

    counting, resumed_calls = _counting()
    _patch(monkeypatch, counting)
    resumed = diagnose(runout_sweep, checkpoint=tmp_path / "kept", **kw)
    # the three finished calibrations were read back, not run again
    assert len(resumed_calls) == len(plain_calls) - 3
    assert _document(resumed) == _document(plain)
    assert resumed.tables["before"].equals(plain.tables["before"])

    # finished: a rerun reads every step back, the nominal update's too
    counting, again_calls = _counting()
    _patch(monkeypatch, counting)

    def not_again(*args, **kw):
        raise AssertionError("the nominal update was computed again")

    monkeypatch.setattr(D, "update_nominal_model", not_again)
    again = diagnose(runout_sweep, checkpoint=tmp_path / "kept", **kw)
    assert again_calls == [] and _document(again) == _document(plain)


def test_a_checkpoint_of_other_inputs_is_started_over(tmp_path):
    calls = []

    def work(x):
        calls.append(x)
        return x + 1

    Checkpoint(tmp_path, {"budget": FAST}).step("step", 1, lambda: work(1))
    other = Checkpoint(tmp_path, {"budget": replace(FAST, max_nfev=9)})
    assert list(tmp_path.glob("*.pkl")) == []  # the other run's steps are gone
    assert other.step("step", 1, lambda: work(1)) == 2 and calls == [1, 1]
    same = Checkpoint(tmp_path, {"budget": replace(FAST, max_nfev=9)})
    assert same.step("step", 1, lambda: work(1)) == 2 and calls == [1, 1]
    assert (same.reused, same.computed) == (1, 0)


def test_a_run_that_keeps_no_step_leaves_no_directory(tmp_path):
    """A diagnosis that fails on the user's data before its first step (a channel the
    file lacks) writes nothing into the output folder."""
    measured, _ = make_trial(None, 1, speeds=SPEEDS[:3], n_samples=400)
    with pytest.raises(ValueError, match="xB"):
        diagnose(measured[["speed", "t", "xO1", "yO1"]], channels=["xO1", "xB"],
                 checkpoint=tmp_path / "out" / ".checkpoint")
    assert not (tmp_path / "out").exists()


def test_an_unreadable_step_is_computed_again(tmp_path):
    kept = Checkpoint(tmp_path, "inputs")
    kept.step("step", "key", lambda: 1)
    (file,) = tmp_path.glob("step-*.pkl")
    file.write_bytes(b"not a pickle")
    assert Checkpoint(tmp_path, "inputs").step("step", "key", lambda: 2) == 2


def test_a_key_of_an_object_without_a_value_is_refused(tmp_path):
    with pytest.raises(TypeError, match="cannot hold a object"):
        fingerprint([1, object()])


finite = st.floats(allow_nan=False, allow_infinity=False)


@given(st.dictionaries(st.text(max_size=4), finite, max_size=6))
def test_a_key_is_its_value_whatever_the_order_of_a_mapping(d):
    assert fingerprint(d) == fingerprint(dict(reversed(list(d.items()))))


@given(st.lists(finite, min_size=1, max_size=8), st.data())
def test_keys_of_different_arrays_differ(values, data):
    a = np.array(values)
    i = data.draw(st.integers(0, a.size - 1))
    b = a.copy()
    b[i] = data.draw(finite.filter(lambda v: np.float64(v).tobytes() != a[i].tobytes()))
    assert fingerprint(a) != fingerprint(b)
    assert fingerprint(a) == fingerprint(a.copy())
    # a list is not the array of its values, nor a tuple the list
    assert fingerprint(values) != fingerprint(a)
    assert fingerprint(tuple(values)) != fingerprint(values)
