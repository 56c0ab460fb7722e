"""The human side (plant + human-side controller) packaged as an FMI 2.0 co-simulation FMU.

The FMU's C code is generated from the same CasADi definitions as :mod:`hp_model`; its
integration is the algorithm of :class:`hp_model.simulator.HybridSimulator` (see README.md).
Depends only on :mod:`hp_model`.
"""

from human_fmu.build import MODEL_IDENTIFIER, BuildInfo, FmuBuildError, build_fmu
from human_fmu.initial import initial_state
from human_fmu.perturbation import perturbed_thetas

__all__ = ["MODEL_IDENTIFIER", "BuildInfo", "FmuBuildError", "build_fmu",
           "initial_state", "perturbed_thetas"]
