"""The examples run as written, and ``sknarx paper`` works end to end (quick mode)."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# run where their outputs are pinned, so that a two-minute example does not run twice
RUN_ELSEWHERE = {Path("examples/rk4/identify_unbalance.py"): "tests/test_unbalance.py",
                 Path("examples/rk4/diagnose_rk4.py"): "tests/test_rk4_real.py",
                 Path("examples/04_gap_diagnosis.py"): "tests/test_gap_diagnose.py",
                 Path("examples/silverbox.py"): "tests/test_narx_simulation_error.py"}
EXAMPLES = sorted(p.relative_to(ROOT) for p in (ROOT / "examples").rglob("*.py")
                  if p.relative_to(ROOT) not in RUN_ELSEWHERE)


@pytest.fixture(scope="module")
def clone(tmp_path_factory):
    """The repository's tracked files copied to a folder with no ``../shared`` beside it."""
    dest = tmp_path_factory.mktemp("user") / "sknarx-clone"
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split()
    for name in files:
        src = ROOT / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    assert not (dest.parent / "shared").exists()
    return dest


@pytest.mark.slow
@pytest.mark.parametrize("path", EXAMPLES, ids=str)
def test_example_runs_in_a_clone_without_shared_data(path, clone, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(clone), "MPLBACKEND": "Agg"}
    res = subprocess.run([sys.executable, str(clone / path)], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.strip()
    probe = subprocess.run([sys.executable, "-c", "import sknarx; print(sknarx.__file__)"],
                           cwd=tmp_path, env=env, capture_output=True, text=True)
    assert probe.stdout.startswith(str(clone)), "the example must import the clone's package"


def test_examples_run_elsewhere_exist_and_are_run_there():
    for path, test in RUN_ELSEWHERE.items():
        assert (ROOT / path).exists() and path.name in (ROOT / test).read_text()


@pytest.mark.slow
def test_paper_command_quick(tmp_path):
    out = tmp_path / "paper"
    res = subprocess.run([sys.executable, "-m", "sknarx", "paper", "--out", str(out), "--quick",
                          "--quiet"], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    m = json.loads((out / "metrics.json").read_text())
    for key in ("critical_speed", "selected_terms", "aerr", "validation", "settings"):
        assert key in m
    assert {"speed", "nrmse", "amp1x_rel_error"} <= set(m["validation"][0])
    assert m["settings"]["sampling_rate_hz"] == 1000.0
    assert "sknarx paper" in m["command"]
    html = (out / "report.html").read_text()
    assert "data:image/png;base64," in html and m["sknarx_version"] in html
    for name in ("table3_terms_aerr.csv", "table4_coefficient_functions.csv", "model.json",
                 "fig2_amplitude_curve.png", "fig10_validation_213.6.png", "runup.png",
                 "validity_tests.png", "summary_improved-spline.csv",
                 "speed_function_paper.csv", "validity_tests_paper.csv"):
        assert (out / name).exists(), name
    # the model-judging outputs: validity verdicts per model, the results tables
    assert set(m["validity_tests"]) == {"paper", "improved", "improved-spline"}
    assert {"speed", "term", "coef", "std_err", "aerr"} <= set(m["summary_per_speed"][0])
    assert "Judging the models" in html and "phi_ee" in html
    # no value is a string standing for a number that is not there (pooled rows: null)
    def strings(x):
        if isinstance(x, dict):
            return [s for v in x.values() for s in strings(v)]
        if isinstance(x, list):
            return [s for v in x for s in strings(v)]
        return [x] if isinstance(x, str) else []

    assert "nan" not in {s.lower() for s in strings(m)}
    pooled = [r for rows in m["validity_tests"].values() for r in rows if r["scope"] == "pooled"]
    assert pooled and all(r["speed"] is None for r in pooled)
    # the printed total AERR is not rounded up to a whole it is short of
    printed = res.stdout.split("total AERR ")[1].split(" %")[0]
    assert float(printed) < 100 or m["aerr_total"] >= 100
    assert "well determined" not in html


def test_cli_reports_bad_usage():
    res = subprocess.run([sys.executable, "-m", "sknarx", "paper"], capture_output=True,
                         text=True)
    assert res.returncode != 0 and "--out" in res.stderr


def test_api_reference_is_generated_from_current_docstrings():
    sys.path.insert(0, str(ROOT / "docs"))
    import gen_api

    text = gen_api.render()
    assert (ROOT / "docs" / "api.md").read_text() == text, "run python docs/gen_api.py"
    for name in ("SpeedScheduledNarx", "CommonStructureEFOR", "NarxTermDictionary",
                 "RotorBearingSimulator", "Examples", "sknarx.gap.diagnose",
                 "sknarx.datasets.load_rk4_runup", "correlation_tests"):
        assert name in text
    assert "(undocumented)" not in text


