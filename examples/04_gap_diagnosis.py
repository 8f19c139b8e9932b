"""Diagnose a synthetic measurement whose unmodelled effect is withheld.

Run: python examples/04_gap_diagnosis.py
"""

import numpy as np

from sknarx.gap import diagnose
from sknarx.gap.report_text import effect_parameters
from sknarx.testing import make_trial

# A 'rig' with slow-roll runout, a few percent of stiffness/damping/unbalance mismatch,
# noise and keyphasor jitter: the diagnoser only sees the table.
speeds = tuple(np.linspace(81.7, 276.5, 6).round(4))
measured, truth = make_trial("runout", seed=7, speeds=speeds, n_samples=1000)
print(measured.head())

result = diagnose(measured, candidates=("runout", "crack", "anisotropy"))
print("verdict:", result["verdict"],
      f"- {100 * result['shrink']:.0f} % of the held-out gap removed")
for r in result["ranking"]:
    name = r["effect"] if isinstance(r["effect"], str) else " + ".join(r["effect"])
    print(f"  {name:24s} {100 * r['shrink']:6.1f} % removed; "
          f"{effect_parameters(r['effect'], r['params'])}")
for w in result["where"][:2]:
    print(f"where: {w['order']} at {w['channel']} ({w['window']}), "
          f"{100 * w['share']:.1f} % of the gap")
print("withheld truth:", truth["effects"])
