"""The diagnosis end to end on the blind benchmark's independent plants (fast subset).

One trial of the second derivation and one of the ROSS plant
(``validation/plants``), each against a reduced library: a regression pin of the
diagnosis on plants whose simulation code and effect models are not ``sknarx.rotor``'s,
not a rate (the rates are ``validation``'s, in ``docs/validation.md``).
"""

import warnings

import pytest

from validation.plants.families import CHANNELS, draw_trial, make_family_trial


def _diagnose_family_trial(kind, seed, family, candidates):
    """Diagnosis of one benchmark trial with a reduced library, and its oracle's shrink."""
    from sknarx.gap import diagnose
    from validation.plants.families import feature_gap

    meas, truth, oracle, _ = make_family_trial(kind, seed, family)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(meas, channels=list(CHANNELS), candidates=candidates)
    held = d["split"]["heldout_speeds"]
    e_oracle, _ = feature_gap(meas, oracle, held)
    return d, 1.0 - e_oracle / d["gap_before"]["heldout_excess"]


@pytest.mark.slow
def test_diagnosis_names_per_probe_runout_on_the_second_derivation():
    # end to end on the independent plant (its housings, its reading of the paper, the
    # families' measurement chain): the benchmark's runout 7013, each probe its own
    # slow-roll vector. (The second plant's rub 7001, pinned here until 2953d1d, took
    # 140 s and is named rub + misalignment -- the pair rule accepts misalignment's free
    # 2x on the rub's model-form residual; it is the blind benchmark's to score.)
    import numpy as np

    d, oracle_shrink = _diagnose_family_trial("runout", 7013, "second",
                                              ["runout", "speed-fluctuation"])
    assert d["verdict"] == "runout", d["ranking"][:2]
    assert d["shrink"] >= 0.9 * oracle_shrink
    truth = draw_trial("runout", 7013, "second")  # the drawn truth, not another sweep
    fit = next(r for r in d["ranking"] if r["effect"] == "runout")["params"]
    for ch, (amp, phase, _, _) in truth["effects"]["runout"].items():
        got = fit[ch]["1x_m"] * np.exp(1j * np.radians(fit[ch]["1x_deg"]))
        err = abs(got - amp * np.exp(1j * phase)) / amp
        # journals 0.01-0.02. The disks' 30 um runout under a 600-1000 um 1x response
        # trades with the stiffness scale, which the plant's disk 1x (different in form
        # from the updated model's) does not pin: harmonics agree to 30 % (the rule's
        # harmonic_rtol), so the journals' 2x do not hold the stiffness scale; the
        # held-out shrink is 0.998 whatever the disks' runout
        assert err < (0.1 if ch[1:] in ("A", "B") else 0.75), (ch, err)


@pytest.mark.slow
def test_diagnosis_leaves_a_line_pickup_on_the_ross_plant_unexplained():
    pytest.importorskip("ross")
    # a 50 Hz pickup is outside the library; the bearing clearance's broadband rattle and
    # a speed fluctuation's sidebands match most of its energy (here 95 % of the held-out
    # excess) while breaking the other features (breadth -0.85): the verdict must not
    # name them
    d, _ = _diagnose_family_trial("line-frequency", 12, "ross",
                                  ["clearance", "speed-fluctuation"])
    assert d["gap_before"]["per_feature"] > d["gap_before"]["floor"]["floor_per_feature"]
    assert d["verdict"] == "unexplained", d["ranking"][:2]


@pytest.mark.slow
def test_an_effect_free_second_plant_sweep_is_no_gap_with_its_update_uncertainty():
    # the blind benchmark's effect-free second-plant trial 15000: its housings, its
    # reading of the clearance and of c_O1, c_O2 (on the disks' tilt) make the journals'
    # vertical 2x/3x differ from sknarx's rotor (bearing B's 3x at 190 rad/s: 0.5 um
    # measured, 0.04 um modelled). The update finds the tilt reading and carries what it
    # left uncertain into the harmonics' tolerance: the gap is within the sweep's noise
    from sknarx.gap import diagnose
    from sknarx.gap.updating import DEFAULT_PARAMETERS

    meas, *_ = make_family_trial(None, 15000, "second")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(meas, channels=list(CHANNELS), candidates=())
    assert d["verdict"] == "no-gap"
    assert any("tilt_share_O" in u for u in d["nominal_update"]["updates"])
    # two sigma points per updated parameter
    assert (d["nominal_update"]["harmonic_spread"]["sigma_points"]
            == 2 * len(DEFAULT_PARAMETERS))
    assert d["gap_before"]["per_feature"] < 0.5 * d["gap_before"]["floor"]["floor_per_feature"]


@pytest.mark.slow
def test_a_soft_pedestal_on_the_second_plant_is_not_taken_as_model_form_tolerance():
    # the blind benchmark's anisotropy 16027 (second plant, soft vertical pedestals): the
    # isotropic update cannot follow the split, and a per-channel tolerance took it (yA's
    # misfit 15 % against xA's 3 %: gap 0.14 per feature, no-gap). A probe pair's
    # directions share one tolerance, the smaller (0.48 per feature), and that tolerance
    # admits a larger or smaller circle, not an ellipse: the disk's elliptic orbit,
    # which no isotropic parameter makes, now leads a gap (measured 0.78, O1's 1x 86 %
    # of it) that the same plant without its pedestal does not have
    from sknarx.gap import diagnose

    meas, truth, _, free = make_family_trial("anisotropy", 16027, "second")
    assert truth["effects"]["anisotropy"]["soft_axis"] == "y"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(meas, channels=list(CHANNELS), candidates=())
        d_free = diagnose(free, channels=list(CHANNELS), candidates=())
    upd = d["nominal_update"]
    own, used = upd["channel_misfit_1x"], upd["model_tolerance_1x"]
    assert own["yA"] > 3 * own["xA"]
    assert used["yA"] == used["xA"] == own["xA"]
    floor = d["gap_before"]["floor"]["floor_per_feature"]
    assert d["gap_before"]["per_feature"] > 2 * floor
    assert d_free["gap_before"]["per_feature"] < d_free["gap_before"]["floor"]["floor_per_feature"]
    excess = d.tables["before"].groupby(["channel", "feature"]).excess.sum()
    assert excess[[("xO1", "1x"), ("yO1", "1x")]].sum() > 0.5 * excess.sum()
