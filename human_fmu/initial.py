"""The FMU's initial state in Python: ``start_<d>`` of :mod:`hp_model.placement`, the same
generated function the FMU's C calls in its initialization.

With zero prosthesis offsets the initial state is (q0, qd0) unchanged.  Otherwise the knee
and ankle offsets are added to th_pk and th_pa, the human joints are put on their outputs at
the phase of the resulting stance knee and ankle (the gait parameters ``theta`` of the
domain, as given: not the human's perturbation), and the walker is placed on its stance foot
where q0 has it, the base velocity solving J_foot qd = 0: the state a closed-loop scenario
with the same offsets starts from (:func:`orchestrator.experiments.scenarios.initial_state`).
The placement is the paper's graph's; an FMU of another graph starts from (q0, qd0) as given
and refuses offsets.
"""

from __future__ import annotations

import numpy as np

from hp_model.closed_loop import ClosedLoop
from hp_model.domains import DomainGraph


def initial_state(closed_loop: ClosedLoop, theta: np.ndarray, q0: np.ndarray,
                  qd0: np.ndarray, domain: str, offset_knee: float = 0.0,
                  offset_ankle: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(q, qd) the FMU starts from, given its parameters (see the module docstring)."""
    if closed_loop.model.graph != DomainGraph.PAPER:
        if offset_knee != 0.0 or offset_ankle != 0.0:
            raise ValueError(f"prosthesis offsets place the walker on the paper's graph; the "
                             f"{closed_loop.model.graph} graph's FMU starts from (q0, qd0)")
        return np.array(q0, dtype=float), np.array(qd0, dtype=float)
    return closed_loop.start_state(domain, q0, qd0, theta, (offset_knee, offset_ankle))
