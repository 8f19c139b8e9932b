"""Where a soft pedestal goes: the update's parameters or the 1x model-form tolerance.

A blind trial's soft pedestal (``anisotropy``) on an independent plant often ends
``no-gap``: after the nominal update the gap per held-out feature is under the floor
although the pedestal moves the measurement by many times it. This splits the two things
that can take it. For each FAMILY:SEED anisotropy trial it diagnoses, with the search
stopped before any candidate (only the update and the gap before), the measured sweep
and the same plant without the pedestal (noise-free: ``families.make_family_trial``'s
``free``), each with the package's 1x model-form tolerance and with none beyond the
comparison's own (``sknarx.gap.diagnosis._common_1x_tolerance`` patched to give none,
inside ``try/finally``). A pedestal the tolerance hides shows without it far above its
effect-free plant; one the update's parameters absorb does not. Each channel's relative
1x tolerance (``model_tolerance_1x``) is recorded beside it.

    python benchmarks/bench_gap_pedestal_tolerance.py second:31042 second:31057 ross:31039

Writes ``results/gap_pedestal_tolerance.json``.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import table, write_json  # noqa: E402
from plants.families import make_family_trial  # noqa: E402

import sknarx.gap.diagnosis as diagnosis  # noqa: E402
from sknarx.gap import DiagnosisSettings, diagnose  # noqa: E402


def gap_before(measured, tolerance):
    """The updated nominal model's gap per held-out feature (no candidate searched) and
    each channel's relative 1x model-form tolerance the diagnosis used."""
    settings = replace(DiagnosisSettings(), no_gap_per_feature=float("inf"))
    kept = diagnosis._common_1x_tolerance
    try:
        if not tolerance:
            diagnosis._common_1x_tolerance = lambda update: {}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            d = diagnose(measured, settings=settings)
        tol = d["nominal_update"]["model_tolerance_1x"] if tolerance else {}
        return d["gap_before"]["per_feature"], tol
    finally:
        diagnosis._common_1x_tolerance = kept


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trials", nargs="+", help="FAMILY:SEED of anisotropy trials")
    args = ap.parse_args()
    rows = []
    for item in args.trials:
        family, seed = item.split(":")
        measured, truth, _, free = make_family_trial("anisotropy", int(seed), family)
        row = {"family": family, "seed": int(seed), "pedestal": truth["effects"]["anisotropy"]}
        for name, sweep in (("measured", measured), ("without_pedestal", free)):
            for tolerance in (True, False):
                key = f"{name}_{'tolerance' if tolerance else 'no_tolerance'}"
                row[key], tol = gap_before(sweep, tolerance)
                if tolerance:
                    row[f"{name}_1x_tolerance"] = tol
                print(f"  {item} {key}: {row[key]:.3f} per feature"
                      + (f"; 1x tolerance {', '.join(f'{c} {t:.3f}' for c, t in tol.items())}"
                         if tol else ""), flush=True)
        rows.append(row)
    table([[r["family"], r["seed"], f"{r['measured_tolerance']:.3f}",
            f"{r['measured_no_tolerance']:.3f}", f"{r['without_pedestal_tolerance']:.3f}",
            f"{r['without_pedestal_no_tolerance']:.3f}"] for r in rows],
          ["family", "seed", "measured, 1x tol.", "measured, none",
           "without pedestal (noise-free), 1x tol.", "without, none"])
    write_json("gap_pedestal_tolerance", {
        "what": "gap per held-out feature after the nominal update, no candidate searched, "
                "with the package's 1x model-form tolerance and with none",
        "command": "python benchmarks/bench_gap_pedestal_tolerance.py " + " ".join(args.trials),
        "trials": rows})


if __name__ == "__main__":
    main()
