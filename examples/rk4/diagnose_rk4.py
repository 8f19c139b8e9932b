"""Diagnose the real RK-4 run-up (order-domain Bode data) against its rotor file.

The run-up ships with sknarx (``sknarx.datasets.load_rk4_runup``), so this runs in any
clone, from any folder:
    python examples/rk4/diagnose_rk4.py [OUT]
It is the same as, from the repository root of a checkout with ``../shared`` beside it,
    sknarx gap --measured ../shared/data/rk4-runup/runup_bode.csv \\
               --rotor examples/rk4/rotor.toml --out rk4-out
(the shipped file is byte-identical). About a minute and a half on two cores.
"""

import sys
from pathlib import Path

from sknarx.cli import main
from sknarx.datasets import load_rk4_runup

rotor = Path(__file__).resolve().parent / "rotor.toml"
out = sys.argv[1] if len(sys.argv) > 1 else "rk4-out"
code = main(["gap", "--measured", load_rk4_runup().filename, "--rotor", str(rotor),
             "--out", out])
if code:
    sys.exit(code)
