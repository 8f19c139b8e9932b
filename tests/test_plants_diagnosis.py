"""The diagnosis end to end on the blind benchmark's independent plants (fast subset).

One trial of the second derivation and one of the ROSS plant
(``benchmarks/plants``), each against a reduced library: a regression pin of the blind
benchmark on plants whose simulation code and effect models are not ``sknarx.rotor``'s,
not a rate (the rates are ``benchmarks/bench_gap_blind.py``'s, in ``docs/gap.md``).
"""

import sys
import warnings
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from plants.families import CHANNELS, make_family_trial  # noqa: E402

from sknarx.gap import DiagnosisSettings  # noqa: E402


def _diagnose_family_trial(kind, seed, family, candidates):
    """Diagnosis of one benchmark trial with a reduced library, and its oracle's shrink."""
    from plants.families import feature_gap

    from sknarx.gap import diagnose

    meas, truth, oracle, _ = make_family_trial(kind, seed, family)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(meas, channels=list(CHANNELS), candidates=candidates)
    held = d["split"]["heldout_speeds"]
    e_oracle, _ = feature_gap(meas, oracle, held)
    return d, 1.0 - e_oracle / d["gap_before"]["heldout_excess"]


@pytest.mark.slow
def test_diagnosis_names_a_rub_on_the_second_derivation():
    # end to end on the independent plant (its own rub after Muszynska, its housings,
    # its reading of the paper), against a library that includes the second plant's
    # usual pair partner (misalignment). Seed 7001 is the benchmark's rub (named alone
    # on 09ba3c7 and 8e971ee); not every rub on this plant is (docs/gap.md)
    d, oracle_shrink = _diagnose_family_trial("rub", 7001, "second",
                                              ["rub", "misalignment"])
    names = [d["verdict"]] if isinstance(d["verdict"], str) else d["verdict"]
    assert "rub" in names, d["ranking"][:2]
    assert d["shrink"] >= 0.9 * oracle_shrink
    if names != ["rub"]:
        # known (docs/gap.md, "Blind validation"): where the fitted effect leaves a
        # model-form residual, misalignment's free 1x force at a journal and its free 2x
        # take a third of it
        # and the pair rule (pair_gain 0.3) accepts the partner -- measured here with
        # the damper shares in the update: rub leaves 647, rub + misalignment 446
        pytest.xfail(f"the pair rule accepted a partner: {names}")


@pytest.mark.slow
def test_diagnosis_leaves_a_line_pickup_on_the_ross_plant_unexplained():
    pytest.importorskip("ross")
    # a 50 Hz pickup is outside the library; the bearing clearance's broadband rattle and
    # a speed fluctuation's sidebands match most of its energy (here 95 % of the held-out
    # excess) while breaking the other features (breadth -0.85): the verdict must not
    # name them
    d, _ = _diagnose_family_trial("line-frequency", 12, "ross",
                                  ["clearance", "speed-fluctuation"])
    assert d["gap_before"]["per_feature"] > DiagnosisSettings().no_gap_per_feature
    assert d["verdict"] == "unexplained", d["ranking"][:2]
