"""Diagnose the real RK-4 run-up (order-domain Bode data) against its rotor file.

The run-up ships with sknarx (``sknarx.datasets.load_rk4_runup``), so this runs in any
clone, from any folder:
    python examples/rk4/diagnose_rk4.py [OUT]
It is the same as, from the repository root,
    sknarx gap --measured "$(sknarx datasets path rk4-runup)" \\
               --rotor examples/rk4/rotor.toml --out rk4-out
and records that command in its report. About one to one and a half minutes on a
2-core machine (61 s measured inside the test suite): the run-up is too fast to be
quasi-steady, so each bearing calibration and effect fit simulates the order-tracked
run-up response, hundreds of times in all.
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
