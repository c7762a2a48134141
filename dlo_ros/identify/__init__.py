"""Identify stiffness and weight of a string from its observed shapes (msg_docs/fitting.md).

Identify stiffness and weight from observed shapes (issue #16): observations, point-to-curve
residuals, identifiability and the bilevel Levenberg–Marquardt fit (msg_docs/fitting.md).
"""

from .fit import Estimate, FitResult, FitSettings, ObservationFit, fit
from .observations import (
    ForceObservation,
    MassObservation,
    Observation,
    ObservationError,
    ObservationSet,
    ProfileFit,
    TorqueObservation,
    load_observations,
    observation_set_from_dict,
)

__all__ = [
    "Estimate",
    "FitResult",
    "FitSettings",
    "ForceObservation",
    "MassObservation",
    "Observation",
    "ObservationError",
    "ObservationFit",
    "ObservationSet",
    "ProfileFit",
    "TorqueObservation",
    "fit",
    "load_observations",
    "observation_set_from_dict",
]
