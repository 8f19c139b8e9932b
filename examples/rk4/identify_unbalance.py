"""Identify the unbalance of the real RK-4 campaign's sealed conditions from its rotor file.

The campaign ships with sknarx (``sknarx.datasets.load_rk4_unbalance``), so this runs in
any clone, from any folder:
    python examples/rk4/identify_unbalance.py [OUT]
It is the same as, from the repository root,
    sknarx unbalance --features "$(sknarx datasets path rk4-unbalance)" \\
                     --rotor examples/rk4/rotor.toml --out ub-out
About 80 s on two cores: most of it is the
leave-one-condition-out cross-validation against the influence-coefficient and
random-forest peers. Then it prints the cross-validated scores and the predictions.
"""

import json
import sys
from pathlib import Path

import pandas as pd

from sknarx.cli import main
from sknarx.datasets import load_rk4_unbalance

rotor = Path(__file__).resolve().parent / "rotor.toml"
out = Path(sys.argv[1] if len(sys.argv) > 1 else "ub-out")
code = main(["unbalance", "--features", load_rk4_unbalance().filename, "--rotor", str(rotor),
             "--out", str(out)])
if code:
    sys.exit(code)

doc = json.loads((out / "unbalance.json").read_text())
scores = pd.DataFrame(doc["cross_validation"]["methods"]).T
print("leave-one-condition-out on the labelled conditions:")
print(scores.to_string(float_format=lambda v: f"{v:.3g}"))
print("\npredictions for the unlabelled conditions (g mm, degrees):")
print(pd.read_csv(out / "predictions.csv").to_string(index=False, float_format="{:.1f}".format))
