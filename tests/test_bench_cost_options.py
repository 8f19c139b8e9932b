"""The cost benchmark's peer (``benchmarks/bench_gap_cost.py --peer-settings``): the
settings it is timed against are read from the command line, and a misspelt field or a
value that is not a literal ends the run with a usage line, not a traceback."""

import argparse
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_gap_cost as cost  # noqa: E402


def _peer(text, ap):
    import dataclasses

    import _common

    from sknarx.gap import DiagnosisSettings

    return _common.setting_overrides(
        [text], [f.name for f in dataclasses.fields(DiagnosisSettings)], ap,
        "--peer-settings", "n_probe=64")


def test_peer_settings_are_diagnosis_settings_fields_with_literal_values():
    ap = argparse.ArgumentParser()
    assert _peer("warm_lead_s=None", ap) == {"warm_lead_s": None}
    assert _peer("n_probe=64, settled_sigma=0.2", ap) == {
        "n_probe": 64, "settled_sigma": 0.2}
    assert _peer("", ap) == {}
    # a tuple keeps its commas: pairs split only before the next field=
    assert _peer("order_floors_z2=(2.5, 1.8, 1.7),n_probe=64", ap) == {
        "order_floors_z2": (2.5, 1.8, 1.7), "n_probe": 64}
    assert _peer("order_floors_z2=2.5,1.8,1.7", ap) == {"order_floors_z2": (2.5, 1.8, 1.7)}


@pytest.mark.parametrize("text, named", [("nprobe=64", "nprobe"), ("n_probe", "n_probe"),
                                         ("n_probe=sixty", "sixty")])
def test_a_wrong_peer_setting_is_a_usage_error_naming_it(text, named, capsys):
    with pytest.raises(SystemExit) as exc:
        _peer(text, argparse.ArgumentParser(prog="bench_gap_cost.py"))
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert named in err and "--peer-settings" in err and "Traceback" not in err


def test_the_cost_benchmark_reads_its_peer_with_the_shared_parser():
    """One parser for both benchmarks that change settings (the cost A/B's peer and the
    rescoring's what-ifs): neither keeps its own."""
    import rescore_gap_blind

    assert cost.setting_overrides is rescore_gap_blind.setting_overrides
    assert not hasattr(cost, "_settings_from") and not hasattr(rescore_gap_blind, "_value")


def test_the_machine_factor_is_the_references_median_over_its_baseline():
    """Times are quoted at the baseline machine's speed by dividing by this factor, so it
    must be the median of the reference's runs over the baseline file's own figure (and
    name where that came from)."""
    import json

    import _common

    base = json.loads((_common.RESULTS / _common.REFERENCE_BASELINE).read_text())
    then = base["one_speed"]["solve_ivp_rk45_median_s"]
    ref = _common.machine_reference([then, 3 * then, 2 * then])
    assert ref["seconds"] == pytest.approx(2 * then)
    assert ref["factor"] == pytest.approx(2.0)
    assert ref["baseline_s"] == then and ref["runs_s"] == [then, 3 * then, 2 * then]
    assert base["machine"]["git_commit"][:7] in ref["baseline_from"]


def test_the_reference_is_timed_after_its_simulator_is_built(monkeypatch):
    """The baseline timed the integration alone: the simulator and its static
    equilibrium are built before the first timed call, not inside it."""
    import _common

    events = []
    monkeypatch.setattr(_common, "_reference_simulator", lambda: events.append("built"))
    monkeypatch.setattr(_common, "reference_workload", lambda: events.append("run"))
    _, runs_s, _ = _common.time_reference(2)
    assert events == ["built", "run", "run"] and len(runs_s) == 2


def test_the_cost_benchmark_reads_readings_as_the_blind_run_does():
    """``--reading`` is the blind run's syntax and parser (one for both), so the readings'
    cost is measured on what the blind run diagnoses; a malformed one is a usage line."""
    import subprocess

    import bench_gap_blind

    assert cost.parse_readings is bench_gap_blind.parse_readings
    ap = argparse.ArgumentParser()
    assert cost.parse_readings(ap, ["tilt:tilt_share_O=1"]) == {"tilt": {"tilt_share_O": 1.0}}
    assert cost.parse_readings(ap, []) is None
    run = subprocess.run([sys.executable, cost.__file__, "--reading", "tilt_share_O=1"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 2
    assert "--reading" in run.stderr and "Traceback" not in run.stderr


def test_the_looseness_alone_benchmark_names_a_usage_error(capsys):
    import bench_gap_looseness_alone as bench

    with pytest.raises(SystemExit) as exc:
        bench.main(["--seeds", "55058,x"])
    assert exc.value.code == 2
    assert "--seeds takes integers" in capsys.readouterr().err


def test_the_looseness_alone_names_three_loose_joints_in_the_reading_and_none_as_given():
    """results/bench_gap_looseness_alone.json (docs/gap_validation.md, *The looseness
    alone in the second plant's reading*): the ceiling a search of readings has on the
    second plant's visible loose joints of 51000-59000 -- the candidate's form names 3 of
    14 in the reading tilt_share_O = 1 (each with its residual within 20 % of the
    truth) and none on the rotor as given."""
    import json

    import bench_gap_looseness_alone as bench

    report = json.loads((bench.RESULTS / "bench_gap_looseness_alone.json").read_text())
    assert report["n_seeds"] == len(bench.SEEDS) == 14
    assert report["named"] == {"as given": 0, "tilt_share_O = 1": 3}
    logged = bench.logged(report["code"])
    named = {s for (s, r), rec in logged.items()
             if r == "tilt_share_O = 1" and rec["verdict"] == "looseness"}
    assert named == {51058, 55058, 59010}
    for s in named:
        rec = logged[(s, "tilt_share_O = 1")]
        assert abs(rec["params"]["residual"] / rec["truth"]["residual"] - 1) < 0.2, s
