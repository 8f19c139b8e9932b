"""What the commands write and where: the output folder is tried before any work, the
recorded command reproduces the run, the shipped datasets are found by name, and a
second Ctrl-C leaves no traceback."""

import os
import signal
import subprocess
import sys
import time

import pytest

from sknarx import cli
from sknarx.datasets import DATASETS, dataset_path, load_rk4_runup, load_rk4_unbalance


def _never(*args, **kwargs):
    raise AssertionError("the computation ran before --out was checked")


def _unwritable(tmp_path):
    """Folders no one can create: below a file, and (not as root) in a read-only one."""
    (tmp_path / "file").write_text("x")
    places = [tmp_path / "file" / "out"]
    if os.name == "posix" and os.geteuid() != 0:
        ro = tmp_path / "read-only"
        ro.mkdir()
        ro.chmod(0o500)
        places.append(ro / "out")
    if os.path.isdir("/proc/self"):
        places.append("/proc/sknarx-out")
    return places


@pytest.mark.parametrize("command", ["paper", "gap", "unbalance", "gap-bode"])
def test_an_unwritable_out_stops_before_any_computation(command, tmp_path, capsys,
                                                        monkeypatch):
    import sknarx.bode
    import sknarx.gap
    import sknarx.reproduce
    import sknarx.unbalance

    for module, name in ((sknarx.reproduce, "run_study"), (sknarx.gap, "diagnose"),
                         (sknarx.bode, "diagnose_order_domain"),
                         (sknarx.unbalance, "identify_unbalance")):
        monkeypatch.setattr(module, name, _never)
    rotor = os.path.join(os.path.dirname(__file__), "..", "examples", "rk4", "rotor.toml")
    measured = tmp_path / "m.csv"
    measured.write_text("speed,t,xO1\n" + "".join(f"{w},{i / 1000},1e-6\n" for w in
                                                  (90, 110, 130, 150) for i in range(64)))
    for place in _unwritable(tmp_path):
        argv = {"paper": ["paper", "--out", str(place), "--quick"],
                "gap": ["gap", "--measured", str(measured), "--out", str(place)],
                "gap-bode": ["gap", "--measured", load_rk4_runup().filename, "--rotor",
                             rotor, "--out", str(place)],
                "unbalance": ["unbalance", "--features", load_rk4_unbalance().filename,
                              "--rotor", rotor, "--out", str(place)]}[command]
        assert cli.main([*argv, "-q"]) == 2, place
        err = capsys.readouterr().err
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert len(lines) == 1 and "Traceback" not in err, err
        assert f"--out {place}: cannot write there" in lines[0]


def test_the_recorded_command_is_the_one_that_ran_not_the_callers_argv(tmp_path,
                                                                      monkeypatch):
    """A script that calls ``cli.main([...])`` (as the RK-4 example does) records the
    ``sknarx`` command it ran, not its own arguments ("sknarx rk4-out")."""
    import sknarx.unbalance

    seen = {}

    def write(result, out, command):
        seen["command"] = command
        return {"cross_validation": {"n_conditions": 0, "methods": {
            "model-based (this package)": {"mae_gmm": 0.0, "detection": 1.0,
                                           "localisation": 1.0}}}, "predictions": []}

    monkeypatch.setattr(sknarx.unbalance, "identify_unbalance", lambda *a, **k: None)
    monkeypatch.setattr(sknarx.unbalance, "write_unbalance_outputs", write)
    monkeypatch.setattr(sys, "argv", ["identify_unbalance.py", "ub-out"])
    features = load_rk4_unbalance().filename
    rotor = os.path.join(os.path.dirname(__file__), "..", "examples", "rk4", "rotor.toml")
    out = tmp_path / "ub out"
    assert cli.main(["unbalance", "--features", features, "--rotor", rotor, "--out",
                     str(out), "-q"]) == 0
    assert seen["command"] == (f"sknarx unbalance --features {features} --rotor {rotor} "
                               f"--out '{out}' -q")


def test_the_datasets_command_lists_the_shipped_data_and_prints_their_paths(capsys):
    assert cli.main(["datasets"]) == 0
    listing = capsys.readouterr().out
    for name in DATASETS:
        assert name in listing
        assert cli.main(["datasets", "path", name]) == 0
        path = capsys.readouterr().out.strip()
        assert path == dataset_path(name) and os.path.isfile(path)
    assert dataset_path("rk4-runup") == load_rk4_runup().filename
    assert cli.main(["datasets", "path", "silver-box", "-q"]) == 2
    err = capsys.readouterr().err
    assert "no shipped dataset 'silver-box'" in err and "rk4-runup" in err


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
def _default_sigint():
    """Ctrl-C reaches the child as at a terminal: a test worker may ignore SIGINT (some
    libraries set that), and a Python started with SIGINT ignored keeps ignoring it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_a_second_ctrl_c_while_the_workers_wind_down_prints_no_traceback(tmp_path):
    """Ctrl-C twice in quick succession during a diagnosis: one line saying it stopped
    and how to resume, exit 130, no traceback from the threads winding down."""
    import numpy as np

    from sknarx.testing import make_trial

    measured, _ = make_trial("runout", 7, speeds=tuple(np.linspace(81.7, 276.5, 4).round(4)),
                             n_samples=1000)
    path = tmp_path / "m.csv"
    measured.to_csv(path, index=False)
    proc = subprocess.Popen([sys.executable, "-m", "sknarx", "gap", "--measured", str(path),
                             "--out", str(tmp_path / "out"), "--candidates", "runout"],
                            stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            preexec_fn=_default_sigint)
    deadline = time.monotonic() + 300
    # the speed steps run on worker threads from the nominal update on
    while not list((tmp_path / "out" / cli.CHECKPOINT_DIR).glob("*.pkl")):
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    for _ in range(5):
        time.sleep(0.02)
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-2000:]
    assert "Traceback" not in err and "Exception ignored" not in err, err[-2000:]
    assert "interrupted; the same command again resumes from" in err
