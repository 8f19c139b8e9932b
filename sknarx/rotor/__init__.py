"""The physics simulator: parameters, model matrices, bearings, integrator, effects,
and the steady state by harmonic balance."""

from .effects import (
    EFFECTS,
    BreathingCrack,
    ClearanceChange,
    Effect,
    JointLooseness,
    MeasurementNoise,
    Misalignment,
    ProbeRunout,
    Rub,
    SpeedFluctuation,
    SupportAnisotropy,
    SupportFlexibility,
)
from .linear import LinearRotorModel
from .matrices import RotorMatrices, assemble
from .parameters import DOF_NAMES, RotorParameters
from .pedestals import HOUSING_NAMES, Pedestals
from .simulator import RotorBearingSimulator, SimulationDivergenceError
from .steady import HarmonicBalanceError, SteadyState, solve_steady_state
from .sweep_table import load_sweep, save_sweep

__all__ = [
    "RotorBearingSimulator",
    "SimulationDivergenceError",
    "SteadyState",
    "HarmonicBalanceError",
    "solve_steady_state",
    "RotorParameters",
    "DOF_NAMES",
    "HOUSING_NAMES",
    "Pedestals",
    "RotorMatrices",
    "assemble",
    "LinearRotorModel",
    "Effect",
    "EFFECTS",
    "Rub",
    "Misalignment",
    "BreathingCrack",
    "JointLooseness",
    "SupportAnisotropy",
    "SupportFlexibility",
    "ProbeRunout",
    "MeasurementNoise",
    "SpeedFluctuation",
    "ClearanceChange",
    "load_sweep",
    "save_sweep",
]
