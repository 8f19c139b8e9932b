"""Every user mistake ends in one line naming the problem and the fix, exit code 2."""

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from sknarx import cli


def run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "sknarx", *args], capture_output=True,
                          text=True, timeout=300, cwd=cwd)


def assert_one_line_error(res, *needles):
    assert res.returncode == 2, (res.returncode, res.stderr[-2000:])
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, res.stderr
    assert "Traceback" not in res.stderr
    for needle in needles:
        assert needle.lower() in lines[0].lower(), (needle, lines[0])


def steps(tmp_path, name="m.csv", sep=",", scale=1.0, nan=False, columns=("xO1",)):
    """A tiny measured long table (4 speed steps of 128 samples)."""
    rows = []
    for w in (90.0, 110.0, 130.0, 150.0):
        t = np.arange(128) / 1000.0
        row = {"speed": w, "t": t}
        for c in columns:
            row[c] = 1e-5 * scale * np.cos(w * t)
        rows.append(pd.DataFrame(row))
    df = pd.concat(rows)
    if nan:
        df.iloc[5, 2] = np.nan
    path = tmp_path / name
    df.to_csv(path, index=False, sep=sep)
    return path


@pytest.fixture
def out(tmp_path):
    return str(tmp_path / "out")


def test_missing_file(tmp_path, out):
    assert_one_line_error(run("gap", "--measured", str(tmp_path / "nope.csv"), "--out", out),
                          "no file", "check the path")


def test_empty_file(tmp_path, out):
    (tmp_path / "e.csv").write_text("")
    assert_one_line_error(run("gap", "--measured", str(tmp_path / "e.csv"), "--out", out),
                          "is empty")


def test_header_only(tmp_path, out):
    (tmp_path / "h.csv").write_text("speed,t,xO1\n")
    assert_one_line_error(run("gap", "--measured", str(tmp_path / "h.csv"), "--out", out),
                          "no data rows")


def test_semicolon_csv_is_read_by_its_delimiter(tmp_path, out):
    # read correctly: the error is then about the content (no channel column), and names
    # the columns that were found, proving the split
    path = steps(tmp_path, sep=";", columns=())
    assert_one_line_error(run("gap", "--measured", str(path), "--out", out),
                          "no measured channel", "'speed', 't'")


def test_unknown_candidate_rejected_before_any_work(tmp_path, out):
    res = run("gap", "--measured", str(tmp_path / "whatever.csv"), "--out", out,
              "--candidates", "bogus")
    assert_one_line_error(res, "invalid choice", "bogus", "rub")


def test_unknown_channel(tmp_path, out):
    assert_one_line_error(run("gap", "--measured", "m.csv", "--out", out, "--channels", "zz"),
                          "invalid choice", "zz")


def test_wrong_suffix(tmp_path, out):
    (tmp_path / "m.txt").write_text("speed,t,xO1\n1,0,0\n")
    assert_one_line_error(run("gap", "--measured", str(tmp_path / "m.txt"), "--out", out),
                          ".txt", ".csv")


def test_missing_columns(tmp_path, out):
    (tmp_path / "c.csv").write_text("rpm,time,x\n1,0,0\n")
    assert_one_line_error(run("gap", "--measured", str(tmp_path / "c.csv"), "--out", out),
                          "lack column", "speed")


def test_nan_values(tmp_path, out):
    assert_one_line_error(run("gap", "--measured", str(steps(tmp_path, nan=True)), "--out",
                              out), "nan")


def test_millimetres_instead_of_metres(tmp_path, out):
    assert_one_line_error(run("gap", "--measured", str(steps(tmp_path, scale=1e4)), "--out",
                              out), "metres")


def test_too_few_speed_steps(tmp_path, out):
    path = steps(tmp_path)
    df = pd.read_csv(path)
    df[df.speed < 140].to_csv(path, index=False)
    assert_one_line_error(run("gap", "--measured", str(path), "--out", out), "at least 4")


def test_bad_rotor_file(tmp_path, out):
    (tmp_path / "r.toml").write_text("[rotor\nmodel = ")
    assert_one_line_error(run("gap", "--measured", str(steps(tmp_path)), "--rotor",
                              str(tmp_path / "r.toml"), "--out", out), "not valid TOML")
    assert_one_line_error(run("gap", "--measured", str(steps(tmp_path)), "--rotor",
                              str(tmp_path / "none.toml"), "--out", out), "no rotor file")


def test_a_rotor_file_reading_of_an_unknown_parameter(tmp_path, out):
    (tmp_path / "r.toml").write_text('[readings."dampers on the tilt"]\ntilt_shar_O = 1.0\n')
    assert_one_line_error(run("gap", "--measured", str(steps(tmp_path)), "--rotor",
                              str(tmp_path / "r.toml"), "--out", out),
                          "dampers on the tilt", "tilt_shar_O", "RotorParameters")


def test_out_is_a_file(tmp_path):
    (tmp_path / "f").write_text("x")
    assert_one_line_error(run("gap", "--measured", str(steps(tmp_path)), "--out",
                              str(tmp_path / "f")), "is a file")


def test_missing_required_option():
    assert_one_line_error(run("paper"), "--out")


def test_debug_shows_the_traceback(tmp_path, out):
    res = run("gap", "--measured", str(tmp_path / "nope.csv"), "--out", out, "--debug")
    assert res.returncode != 0 and "Traceback" in res.stderr


def test_version_and_help_list_the_choices():
    from sknarx import __version__

    res = run("--version")
    assert res.returncode == 0 and res.stdout.strip() == f"sknarx {__version__}"
    text = run("gap", "--help").stdout
    for word in ("rub", "speed-fluctuation", "xO1", "--quiet", "--verbose", "--debug"):
        assert word in text


def test_cli_choices_are_the_library_names():
    from sknarx.gap import LIBRARY
    from sknarx.gap.measured import TRANSLATIONAL

    assert set(cli.EFFECTS) == set(LIBRARY)
    assert set(cli.CHANNELS) == set(TRANSLATIONAL)


@pytest.fixture(scope="module")
def rk4(tmp_path_factory):
    """The shipped RK-4 run-up and its rotor file, and a folder for broken copies."""
    from pathlib import Path

    from sknarx.datasets import load_rk4_runup

    root = Path(__file__).resolve().parents[1]
    return (Path(load_rk4_runup().filename), root / "examples" / "rk4" / "rotor.toml",
            tmp_path_factory.mktemp("rk4-errors"))


def _broken_rotor(rk4, name, edit):
    _, rotor, work = rk4
    path = work / name
    path.write_text(edit(rotor.read_text()))
    return path


@pytest.mark.parametrize("case, needles", [
    ("no rotor", ("order-tracked (1x Bode) record", "model = 'beam'",
                  "examples/rk4/rotor.toml")),
    ("three revolutions", ("speed bin(s)", "at least 12", "wider speed range")),
    ("negative speeds", ("speeds ('rpm') must be positive", "[measurement]")),
    ("a disk without its mass", ("[[disks]] entry 1 lacks mass",)),
    ("an unknown model", ("model = 'bem'", "'paper'", "'beam'")),
    ("no shaft", ("needs a [shaft] section",)),
    ("no probes", ("names no [[probes]]", "direction")),
])
def test_an_order_domain_record_or_its_rotor_file_wrong(rk4, case, needles, capsys, tmp_path):
    """The order-domain front end (a 1x Bode record against a beam rotor file): each
    mistake one line naming the fix, exit 2 -- before, a Bode file given without
    ``--rotor`` ended in ``internal error (KeyError: 'shaft')`` and a three-revolution
    record in LAPACK's 'SVD did not converge'."""
    bode, rotor, _ = rk4
    measured = bode
    if case == "three revolutions":
        measured = tmp_path / "short.csv"
        pd.read_csv(bode).head(3).to_csv(measured, index=False)
    if case == "negative speeds":
        measured = tmp_path / "negative.csv"
        d = pd.read_csv(bode)
        d.assign(rpm=-d.rpm).to_csv(measured, index=False)
    edits = {
        "a disk without its mass": lambda t: t.replace("mass = 0.8", "", 1),
        "an unknown model": lambda t: t.replace('model = "beam"', 'model = "bem"'),
        "no shaft": lambda t: t.replace("[shaft]", "[shafts]"),
        "no probes": lambda t: t[:t.index("[[probes]]")],
    }
    if case in edits:
        rotor = _broken_rotor(rk4, case.replace(" ", "_") + ".toml", edits[case])
    argv = ["gap", "--measured", str(measured), "--out", str(tmp_path / "out"), "-q"]
    if case != "no rotor":
        argv += ["--rotor", str(rotor)]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle.lower() in lines[0].lower(), (needle, lines[0])


def _in_process_error(capsys, argv, *needles):
    assert cli.main([*argv, "-q"]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle.lower() in lines[0].lower(), (needle, lines[0])


def test_a_csv_that_is_not_text_is_named(tmp_path, capsys):
    path = tmp_path / "random.csv"
    path.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    _in_process_error(capsys, ["gap", "--measured", str(path), "--out", str(tmp_path / "o")],
                      str(path), "not UTF-8 text", "save it as a UTF-8 CSV")


def test_a_parquet_file_without_pyarrow_says_how_to_install_it(tmp_path, capsys,
                                                                 monkeypatch):
    path = tmp_path / "m.parquet"
    path.write_bytes(b"PAR1" + b"\0" * 64 + b"PAR1")

    def no_engine(*args, **kwargs):
        raise ImportError("Unable to find a usable engine; tried using: 'pyarrow', "
                          "'fastparquet'.")

    monkeypatch.setattr(pd, "read_parquet", no_engine)
    _in_process_error(capsys, ["gap", "--measured", str(path), "--out", str(tmp_path / "o")],
                      "m.parquet", 'pip install "sknarx[parquet]"')


def test_a_broken_parquet_file_is_named(tmp_path, capsys):
    pytest.importorskip("pyarrow")
    path = tmp_path / "m.parquet"
    path.write_bytes(b"not a parquet file at all")
    _in_process_error(capsys, ["gap", "--measured", str(path), "--out", str(tmp_path / "o")],
                      str(path), "not a readable parquet file")


def test_records_too_short_for_a_steady_window(tmp_path, capsys):
    from sknarx.testing import make_trial

    measured, _ = make_trial(None, 7, speeds=(81.7, 146.6, 211.5, 276.5), n_samples=400)
    path = tmp_path / "short.csv"
    measured.to_csv(path, index=False)
    _in_process_error(capsys, ["gap", "--measured", str(path), "--out", str(tmp_path / "o")],
                      "0.4 s long", "starts with a transient", "record at least 0.81 s")
