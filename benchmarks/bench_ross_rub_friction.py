"""What ROSS's rub friction adds to the rub's harmonics on the ROSS plant.

ROSS's ``Rubbing`` (``ross/faults/rubbing.py``) takes the friction as ``mu`` times the
normal force component by component, ``(-mu |F_x|, +mu |F_y|)``: one direction wherever
the contact is, where a rig's friction opposes the surface's motion at the contact. The
blind runs name some of ROSS's rubs a crack (a 2x effect). This runs one blind trial's
rub on the ROSS plant three times -- without the rub, with the drawn friction and with
none -- and tables the 1x and 2x at the disk probes speed by speed, so what the
friction law adds can be read beside what the radial contact alone does.

    python benchmarks/bench_ross_rub_friction.py [--seed 35029]

Prints a table and writes ``results/bench_ross_rub_friction.json``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import table, write_json  # noqa: E402
from plants.families import SPEEDS, draw_trial, order_phasors, simulate  # noqa: E402

PROBES = ("xO1", "yO1")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=35029,
                    help="the blind trial whose rub is run (default: ROSS 35029, a rub "
                         "the runs named a crack)")
    args = ap.parse_args(argv)
    truth = draw_trial("rub", args.seed, "ross")
    rub = truth["effects"]["rub"]
    cases = {"no rub": {}, "friction 0": {"rub": dict(rub, friction=0.0)},
             f"friction {rub['friction']:.3f}": {"rub": rub}}
    amp = {}
    for label, physical in cases.items():
        z = order_phasors(simulate("ross", truth, physical), (1.0, 2.0))
        amp[label] = np.abs(z[:, :2, :]) * 1e6  # speeds x (xO1, yO1) x (1x, 2x), um
    rows = []
    for i, w in enumerate(SPEEDS):
        row = [f"{w:.1f}"]
        for label in cases:
            row += [f"{amp[label][i, p, o]:.1f}" for o in (0, 1) for p in range(2)]
        rows.append(row)
    heads = ["speed (rad/s)"] + [f"{label}: {o}x {p} (um)" for label in cases
                                 for o in (1, 2) for p in PROBES]
    print(f"ROSS plant, rub of trial {args.seed}: {rub}")
    table(rows, heads)
    write_json("bench_ross_rub_friction", {
        "seed": args.seed, "rub": rub, "speeds_rad_s": list(SPEEDS),
        "amplitude_um": {label: {f"{o}x": {p: amp[label][:, k, o - 1].tolist()
                                           for k, p in enumerate(PROBES)} for o in (1, 2)}
                         for label in cases}})


if __name__ == "__main__":
    main()
