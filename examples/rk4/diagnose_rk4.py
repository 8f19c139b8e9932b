"""Diagnose the real RK-4 run-up (order-domain Bode data) against its rotor file.

Run from the repository root:
    python examples/rk4/diagnose_rk4.py
equivalent to
    sknarx gap --measured ../shared/data/rk4-runup/runup_bode.csv \
               --rotor examples/rk4/rotor.toml --out rk4-out
"""

import sys

from sknarx.cli import main

sys.exit(main(["gap", "--measured", "../shared/data/rk4-runup/runup_bode.csv",
               "--rotor", "examples/rk4/rotor.toml", "--out", "rk4-out"]))
