"""Steps the human FMU with fmpy under a deterministic prosthesis policy.

Needs only fmpy and numpy (no package of this project): the isolated test runs this file in
a Python where this project is not importable.  The in-process tests import the same
``NominalPD`` and ``run`` so both sides use the same policy function.

    python fmu_runner.py HUMAN.fmu SPEC.json OUT.json

SPEC: {"policy": <NominalPD table>, "periods": n, "dt": s, "tau_from": "output" | "q",
       "real": {name: value}, "integer": {name: value}}
"""

from __future__ import annotations

import json
import sys

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2Discard

#: the FMU's domain words by code (hp_model.domains.Domain; this file may not import it)
DOMAINS = ("ps", "pns")
SENSORS = ("knee_angle", "ankle_angle", "knee_velocity", "ankle_velocity", "foot_load",
           "tau", "t_impact", "socket_Fx", "socket_Fz", "socket_My")
#: outputs that depend on the inputs directly (read again after setting them)
FORCES = ("foot_load", "socket_Fx", "socket_Fz", "socket_My", "stance_Fx", "stance_Fz",
          "stance_My")


class NominalPD:
    """Prosthesis motor torque = the gait's nominal motor torque at the phase tau, plus a PD
    on the nominal knee and ankle angles at tau (joint gains divided by the gear ratios).

    ``table``: {"ratio": [2], "gains": {d: [kp, kd]}, "phase": {d: {"c_row": [12],
    "p_min", "p_max"}}, "nominal": {d: {"tau": [n], "q": [2][n], "qd": [2][n], "u": [2][n]}}}.
    """

    def __init__(self, table: dict) -> None:
        self.ratio = np.asarray(table["ratio"], dtype=float)
        self.gains = {d: tuple(table["gains"][d]) for d in DOMAINS}
        self.c_row = {d: np.asarray(table["phase"][d]["c_row"], dtype=float) for d in DOMAINS}
        self.p = {d: (float(table["phase"][d]["p_min"]), float(table["phase"][d]["p_max"]))
                  for d in DOMAINS}
        self.nom = {d: {k: np.asarray(v, dtype=float) for k, v in table["nominal"][d].items()}
                    for d in DOMAINS}

    def phase(self, domain: str, q: np.ndarray) -> float:
        """tau from the full configuration with the arithmetic of ``HybridSimulator.phase``
        and the FMU's generated ``phase_<d>`` (hp_model.outputs; this file cannot import
        it): the row's products summed in index order, then normalised by the bounds."""
        p_min, p_max = self.p[domain]
        s = 0.0
        for c, x in zip(self.c_row[domain].tolist(), np.asarray(q, float).tolist(), strict=True):
            s += c * x
        return (s - p_min) / (p_max - p_min)

    def __call__(self, domain: str, tau: float, angles: np.ndarray, velocities: np.ndarray
                 ) -> np.ndarray:
        kp, kd = self.gains[domain]
        n = self.nom[domain]
        s = min(max(tau, 0.0), 1.0)
        qn = np.array([np.interp(s, n["tau"], n["q"][i]) for i in range(2)])
        qdn = np.array([np.interp(s, n["tau"], n["qd"][i]) for i in range(2)])
        un = np.array([np.interp(s, n["tau"], n["u"][i]) for i in range(2)])
        return un + (kp * (qn - angles) + kd * (qdn - velocities)) / self.ratio


class HumanFMU:
    """An fmpy FMU2Slave of the human FMU with name-based access."""

    def __init__(self, path: str, unzipdir: str | None = None, instance: str = "human",
                 callbacks=None) -> None:
        self.md = read_model_description(path)
        self.unzipdir = unzipdir or extract(path)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier,
                             instanceName=instance)
        self.fmu.instantiate(callbacks=callbacks)

    def vrs(self, names) -> list[int]:
        return [self.vr[n] for n in names]

    def setup(self, real: dict | None = None, integer: dict | None = None) -> None:
        f = self.fmu
        f.setupExperiment(startTime=0.0)
        if real:
            f.setReal(self.vrs(real), [float(v) for v in real.values()])
        if integer:
            f.setInteger(self.vrs(integer), [int(v) for v in integer.values()])
        f.enterInitializationMode()
        f.exitInitializationMode()

    def free(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


def run(h: HumanFMU, policy: NominalPD, periods: int, dt: float = 1e-3,
        tau_from: str = "output") -> dict:
    """``periods`` samples: read the outputs, apply the policy, doStep(dt); the last sample is
    read without a step after it (like ``HybridSimulator.run``'s log).  ``tau_from`` "q"
    makes the policy compute tau from the ground-truth q (bit-identical to the simulator's
    phase), "output" uses the FMU's tau output (the C computation of the same formula)."""
    log: dict = {}
    for _ in stepper(h, policy, periods, dt, tau_from, log):
        pass
    return log


def stepper(h: HumanFMU, policy: NominalPD, periods: int, dt: float, tau_from: str, log: dict):
    """``run`` one sample at a time (a generator yielding the sample index), filling ``log``."""
    f = h.fmu
    sens = h.vrs(SENSORS)
    qv = h.vrs([f"q[{i}]" for i in range(1, 13)])
    qdv = h.vrs([f"qd[{i}]" for i in range(1, 13)])
    iv = h.vrs(["domain", "steps", "fall_code"])
    fall = h.vrs(["fall"])
    uv = h.vrs(["u_knee", "u_ankle"])
    fv = h.vrs(FORCES)
    log.update(sensors=[], q=[], qd=[], domain=[], u=[], forces=[], impacts=[], fall=False,
               fall_code=0, fall_period=-1)
    steps = 0
    for k in range(periods):
        y = f.getReal(sens)
        q = np.array(f.getReal(qv))
        dom, n_steps, code = f.getInteger(iv)
        log["sensors"].append(y)
        log["q"].append(q.tolist())
        log["qd"].append(f.getReal(qdv))
        log["domain"].append(dom)
        if n_steps != steps:
            log["impacts"].append(y[6])
            steps = n_steps
        if f.getBoolean(fall)[0]:
            log.update(fall=True, fall_code=code, fall_period=k)
            return
        d = DOMAINS[dom]
        tau = policy.phase(d, q) if tau_from == "q" else y[5]
        u = policy(d, tau, np.array(y[0:2]), np.array(y[2:4]))
        log["u"].append(u.tolist())
        f.setReal(uv, u.tolist())
        log["forces"].append(f.getReal(fv))
        if k < periods - 1:
            try:
                f.doStep(k * dt, dt)
            except FMICallException as e:  # a fall: fmi2Discard, seen on the next read
                if e.status != fmi2Discard:
                    raise
        yield k


def main(argv: list[str]) -> int:
    path, spec_path, out_path = argv
    with open(spec_path) as fh:
        spec = json.load(fh)
    h = HumanFMU(path)
    h.setup(spec.get("real"), spec.get("integer"))
    log = run(h, NominalPD(spec["policy"]), spec["periods"], spec["dt"],
              spec.get("tau_from", "output"))
    h.free()
    with open(out_path, "w") as fh:
        json.dump(log, fh)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
