"""D(q) and H(q, qd) against MuJoCo, a second independent rigid-body engine, loading the URDF
export (issue 21: it did not load, massless links carrying joints).  The export bounds the
massless links of the planar chains at 1e-9 kg / 1e-12 kg m^2 for MuJoCo: 1e-11 of the
walker's mass, so the relative tolerance is 1e-7 (Pinocchio's comparison uses 1e-8 on the
same states)."""

from __future__ import annotations

import mujoco
import numpy as np

from hp_model.urdf import to_urdf
from tests.conftest import random_state

N_STATES = 50
REL_TOL = 1e-7


def test_urdf_loads_in_mujoco_and_its_dynamics_match(model, rng):
    mm = mujoco.MjModel.from_xml_string(to_urdf(model.tree))
    assert [mm.joint(i).name for i in range(mm.njnt)] == list(model.coord_names)
    assert mm.nq == mm.nv == model.nq
    assert np.allclose(mm.opt.gravity, [0.0, 0.0, -model.tree.gravity])
    md = mujoco.MjData(mm)
    dom = next(iter(model.domains))
    terms = model.numeric()[f"terms_{dom}"]
    worst_D = worst_H = 0.0
    M = np.zeros((mm.nv, mm.nv))
    for _ in range(N_STATES):
        q, qd = random_state(model, rng, on_socket=False, scale=1.0)
        md.qpos[:], md.qvel[:] = q, qd
        mujoco.mj_forward(mm, md)
        mujoco.mj_fullM(mm, md, M)
        D, H, _, _ = terms(q, qd)
        worst_D = max(worst_D, np.abs(D - M).max() / np.abs(M).max())
        worst_H = max(worst_H, np.abs(H - md.qfrc_bias).max() / max(np.abs(md.qfrc_bias).max(), 1))
    assert worst_D < REL_TOL, f"D differs from MuJoCo's by {worst_D:.2e} (relative)"
    assert worst_H < REL_TOL, f"H differs from MuJoCo's by {worst_H:.2e} (relative)"
