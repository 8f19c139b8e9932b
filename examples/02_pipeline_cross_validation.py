"""The three stages as a scikit-learn Pipeline, cross-validated over held-out speeds.

Run: python examples/02_pipeline_cross_validation.py
"""

import numpy as np
from sklearn.model_selection import GridSearchCV, cross_validate
from sklearn.pipeline import make_pipeline

from sknarx import (
    CommonStructureEFOR,
    LeaveOneSpeedOut,
    NarxTermDictionary,
    SpeedScheduledNarx,
    free_run_scorer,
)
from sknarx.rotor import RotorBearingSimulator

speeds = np.linspace(81.7, 276.5, 10)
sweep = RotorBearingSimulator().sweep(speeds, fs=1000.0, n_samples=4096, settle=0.0,
                                      progress=False)
# The long sample table is the pipeline's X: one row per sample, speed / u / y.
X = sweep.rename(columns={"xO1": "y"})[["speed", "u", "y"]]

pipe = make_pipeline(
    NarxTermDictionary(ny=3, nu=3, degree=3),
    CommonStructureEFOR(esr=0.0, max_terms=10, prune=False),
    SpeedScheduledNarx(speed_basis="spline"),
)
# Hold out each interior speed (the extremes would test extrapolation, not interpolation).
cv = cross_validate(pipe, X, X["y"], groups=X["speed"], cv=LeaveOneSpeedOut(),
                    scoring=free_run_scorer)
print("held-out-speed free-run NRMSE:", np.round(-cv["test_score"], 4))

grid = GridSearchCV(
    pipe,
    {"commonstructureefor__max_terms": [6, 10], "speedschedulednarx__speed_basis":
     ["polynomial", "spline"]},
    cv=LeaveOneSpeedOut(), scoring=free_run_scorer,
)
grid.fit(X, X["y"], groups=X["speed"])
print("best:", grid.best_params_, "NRMSE", round(-grid.best_score_, 4))
