"""From a PHZD solution to the gait artifact (paper Sec. IV-A): the nominal socket force
F*(tau) along the optimized prosthesis stance, the controllers' curves
(:mod:`characterization.gait.controller_curves`), the solver record, the data fit."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from characterization.gait.bezier_fit import fit_bezier
from characterization.gait.controller_curves import fit_controller_curves
from characterization.gait.phzd import DataTargets, PHZDOptions, PHZDResult
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.outputs import GaitParams, VirtualConstraints

SOCKET_DEGREE = 7


def nominal_socket_force(model: HumanProsthesisModel, result: PHZDResult,
                         degree: int = SOCKET_DEGREE) -> np.ndarray:
    """Bezier coefficients (3, degree+1) of F*(tau) over the ps phase, fitted to the socket
    wrench of the collocation trajectory (lam rows 3:6 of ps, the fixed joint's wrench)."""
    tr, p = result.trajectory[Domain.PS], result.params[Domain.PS]
    tau = VirtualConstraints(model, Domain.PS, p.degree).phase(tr["q"], p)
    return fit_bezier(tau, tr["lam"][3:6, :].T, degree).alpha


def build_gait(model: HumanProsthesisModel, result: PHZDResult, targets: DataTargets,
               opt: PHZDOptions, fit_quality: Mapping[Domain, Mapping[str, Any]] | None = None
               ) -> Gait:
    """The gait artifact of a converged optimization."""
    data = {d: GaitParams(np.asarray(targets.alpha[d]), targets.v_hip[d], targets.p_min[d],
                          targets.p_max[d]) for d in PAPER_DOMAINS}
    options = {k: (list(v) if isinstance(v, tuple) else v)
               for k, v in dataclasses.asdict(opt).items()}
    solver = {"status": result.status, "success": result.success,
              "iterations": result.iterations, "seconds": result.solve_seconds,
              "cost": result.cost, **{k: v for k, v in result.stats.items()
                                      if k.startswith("t_wall") or k.startswith("n_call")}}
    return Gait(params=dict(result.params), model_hash=model.parameter_hash(),
                gains=(opt.eps, opt.track_kp, opt.track_kd),
                socket_nominal=nominal_socket_force(model, result),
                controller_curves=fit_controller_curves(model, result.params,
                                                        result.trajectory),
                offsets=dict(result.offsets), durations=dict(result.durations),
                data_params=data, fit_quality=dict(fit_quality or {}),
                trajectory={d: dict(t) for d, t in result.trajectory.items()},
                options=options, solver=solver)
