"""Diagnose a synthetic measurement whose unmodelled effect is withheld.

Run: python examples/04_gap_diagnosis.py
"""

import numpy as np

from sknarx.gap import diagnose
from sknarx.testing import make_trial

# A 'rig' with slow-roll runout, a few percent of stiffness/damping/unbalance mismatch,
# noise and keyphasor jitter: the diagnoser only sees the table.
speeds = tuple(np.linspace(81.7, 276.5, 6).round(4))
measured, truth = make_trial("runout", seed=3, speeds=speeds, n_samples=1000)
print(measured.head())

result = diagnose(measured, candidates=("runout", "crack", "anisotropy"))
print("verdict:", result["verdict"],
      f"- {100 * result['shrink']:.0f} % of the held-out gap removed")
for r in result["ranking"]:
    print(f"  {str(r['effect']):28s} shrink {r['shrink']:6.2f}  params {r['params']}")
print("where:", result["where"][:2])
print("withheld truth:", truth["effects"])
