"""The FMU backend of a sweep run: the human FMU (fmpy, in the worker's process) stepped at
the controller's period with the prosthesis controller in the loop, no bus in between.

Per period k (t = k dt) the controller ticks on the FMU's outputs (what AMPRO3 senses:
knee/ankle angle and rate, foot load clipped at 0 in ps, contact = domain ps), its motor
torque is set and the FMU steps by dt: the order of :meth:`HybridSimulator.run`, so the two
backends log the same samples.  A friction-cone fall (code 5) appears in the FMU's outputs
one period after the simulator's sample (README of ``human_fmu``): that last sample is not
logged.  The result is a :class:`orchestrator.scenarios.ScenarioResult`, summarised by the
same code as the simulator's.

The FMU is instantiated once per worker (:class:`FmuPlant`) and reset for every run; the
human's gait (perturbed thetas) and the initial state are set as parameters, so a run on
the FMU starts exactly where the simulator's run of the same draw starts.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hp_model.domains import DOMAINS
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from human_fmu import FALL_CODES
from human_fmu.instance import FmuInstance
from orchestrator.scenarios import (
    Scenario,
    ScenarioResult,
    knee_reference,
    socket_force_in_tube,
)
from prosthesis_controller import ControllerContext, ProsthesisMeasurement, make_controller

SENSORS = ("knee_angle", "ankle_angle", "knee_velocity", "ankle_velocity", "foot_load", "tau",
           "socket_Fx", "socket_Fz", "socket_My", "socket_pitch")
CONE_FALL = 5  # reported one period late (module docstring)


class FmuPlant(FmuInstance):
    """One instance of the human FMU, extracted into ``workdir`` and instantiated once."""

    def __init__(self, path: Path, workdir: Path) -> None:
        super().__init__(path, unzipdir=workdir / "fmu", instance="sweep")
        info = self.unzipdir / "resources" / "build_info.json"
        self.build_info = json.loads(info.read_text()) if info.is_file() else {}
        self._sens = self.vrs(SENSORS)
        self._ints = self.vrs(("domain", "steps", "fall_code"))
        self._fall = self.vrs(("fall",))
        self._u = self.vrs(("u_knee", "u_ankle"))
        self._n_theta = sum(1 for n in self.vr if n.startswith("theta_ps["))

    def check_gait(self, gait: Gait) -> None:
        """Refuse an FMU built for another gait (its build_info gait hash)."""
        h = self.build_info.get("gait_hash")
        if h is not None and h != gait.hash():
            raise ValueError(f"the FMU was built for gait {h}, not for this gait "
                             f"({gait.hash()})")

    def start(self, thetas: dict[str, np.ndarray], q0: np.ndarray, qd0: np.ndarray) -> None:
        """Reset and initialise for one run: the human tracks ``thetas``, start (q0, qd0)
        in ps, no FMU-side perturbation or offset."""
        self.fmu.reset()
        names: list[str] = []
        vals: list[float] = []
        for d in DOMAINS:
            th = np.asarray(thetas[d], float)
            if th.size != self._n_theta:
                raise ValueError(f"theta_{d} of size {th.size}; the FMU has {self._n_theta}")
            names += [f"theta_{d}[{i + 1}]" for i in range(th.size)]
            vals += th.tolist()
        names += [f"q0[{i + 1}]" for i in range(q0.size)] + \
            [f"qd0[{i + 1}]" for i in range(qd0.size)]
        vals += [float(v) for v in q0] + [float(v) for v in qd0]
        names += ["human_perturbation", "offset_knee", "offset_ankle"]
        vals += [0.0, 0.0, 0.0]
        self.initialize(dict(zip(names, vals, strict=True)),
                        {"human_seed": 0, "initial_domain": 0})


def run_fmu_scenario(plant: FmuPlant, model: HumanProsthesisModel, gait: Gait,
                     ctx: ControllerContext, scenario: Scenario, thetas: dict[str, np.ndarray],
                     q0: np.ndarray, qd0: np.ndarray, dt: float = 1e-3) -> ScenarioResult:
    """One scenario on the FMU (module docstring)."""
    plant.start(thetas, q0, qd0)
    ctrl = make_controller(scenario.controller, gait, ctx.tube, model, context=ctx)
    ctrl.reset()
    f = plant.fmu
    t_log: list[float] = []
    tau_log: list[float] = []
    dom_log: list[int] = []
    q_log: list[tuple[float, float]] = []
    qd_log: list[tuple[float, float]] = []
    fs_log: list[tuple[float, float, float]] = []
    torques: list[np.ndarray] = []
    modes: list[str] = []
    Vs: list[float] = []
    rhos: list[float] = []
    fallbacks = 0
    steps, code, k = 0, 0, 0
    while True:
        t = k * dt
        y = f.getReal(plant._sens)
        dom, steps, code = f.getInteger(plant._ints)
        fell = bool(f.getBoolean(plant._fall)[0])
        if fell and code == CONE_FALL:
            break  # the simulator's fall sample is the previous one
        ps = dom == 0
        m = ProsthesisMeasurement(t=float(t), knee_angle=y[0], ankle_angle=y[1],
                                  knee_vel=y[2], ankle_vel=y[3],
                                  foot_load=max(float(y[4]), 0.0) if ps else 0.0, contact=ps,
                                  socket_pitch=y[9])
        out = ctrl.tick(m)
        dg = out.diagnostics
        u = np.array(out.torque, float)
        torques.append(u)
        modes.append(str(dg.mode))
        Vs.append(float(dg.V))
        rhos.append(float(dg.rho))
        fallbacks = int(dg.fallback_count)
        t_log.append(t)
        tau_log.append(y[5])
        dom_log.append(dom)
        q_log.append((y[0], y[1]))
        qd_log.append((y[2], y[3]))
        fs_log.append((y[6], y[7], y[8]))
        if fell or steps >= scenario.steps:
            break
        f.setReal(plant._u, [float(u[0]), float(u[1])])
        plant.do_step(t, dt)  # False at a fall: the next read sees it and ends the run
        k += 1
    domain = np.array(dom_log, int)
    tau = np.array(tau_log)
    n = domain.size
    failed = code != 0
    fail_t = fail_tau = fail_d = None
    reason = ""
    if failed and n:  # worded, and rounded, as the simulator's reason (scenarios._REASON)
        fail_d = DOMAINS[domain[-1]]
        reason = (f"t = {t_log[-1]:.3f} s, {fail_d}, tau = {tau[-1]:.3f}: "
                  f"{FALL_CODES.get(code, f'fall code {code}')}")
        fail_t, fail_tau = float(f"{t_log[-1]:.3f}"), float(f"{tau[-1]:.3f}")
    ref = np.array([knee_reference(gait, DOMAINS[d], ta) for d, ta in zip(domain, tau,
                                                                           strict=True)])
    bounds, i0 = [], None
    for i, d in enumerate(domain):
        if d == 0 and i0 is None:
            i0 = i
        if d != 0 and i0 is not None:
            bounds.append((i0, i))
            i0 = None
    if i0 is not None:
        bounds.append((i0, n))
    fs = np.array(fs_log, float).reshape(n, 3)
    ps = domain == 0
    return ScenarioResult(
        socket_force=fs, fs_in_tube=socket_force_in_tube(ctx.tube, tau[ps], fs[ps]),
        scenario=scenario, t=np.array(t_log), tau=tau, domain=domain,
        q_p=np.array(q_log).reshape(n, 2), qd_p=np.array(qd_log).reshape(n, 2),
        torque=np.array(torques).reshape(n, 2), knee_ref=ref, mode=modes, V=np.array(Vs),
        rho=np.array(rhos), fallback_count=fallbacks, steps=int(steps), failed=failed,
        reason=reason, fail_t=fail_t, fail_tau=fail_tau, fail_domain=fail_d,
        step_bounds=bounds)
