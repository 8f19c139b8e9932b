"""The physics simulator: parameters, model matrices, bearings, integrator, effects."""

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
from .sweep_table import load_sweep, save_sweep

__all__ = [
    "RotorBearingSimulator",
    "SimulationDivergenceError",
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
