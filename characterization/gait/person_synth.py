"""A synthetic subject with double support (``hpcosim mocap synth --source person --gait
PERSON.json``): the model of a multi-contact gait walking it, as a take.

The motion is the gait's curves (:mod:`characterization.gait.contact_gait`) tracked by the
full model (the simulator in mode full: every torque from the feedback linearization) from
the fitted cycle's start, on the gait's own model (its subject and device), for
``n_strides + 2`` strides: heel strikes, foot-flat landings, heel offs and toe-offs of the
multi-contact graph, dynamically consistent with the model.  Every stride is the gait's
periodic orbit (no per-step variation: a person's would be drawn from a balance the
simulated human does not have yet, issue 38).  The contact events of the truth are the
domain changes of the walk: a prosthesis heel strike (into ``ds_p``), the human toe-off
(``ds_p`` -> ``ps``), the human heel strike (``ds_h``) and the prosthesis toe-off
(``ds_h`` -> ``pns``).  The take is made by :func:`characterization.mocap.
synthetic_subject.take_of_motion` (markers, noise, dropouts, truth), and the subject file
(the gait's subject) is written beside it: ``mocap process take.csv --subject subject.toml``
processes it as the person it is.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from characterization.gait.contact_gait import DEGREE, GAINS, contact_gait_of, start_state
from characterization.gait.multicontact import GRAPH
from characterization.gait.multicontact_artifact import ContactCycle, load_contact_cycle
from characterization.mocap.synthetic_gait import GaitEvents
from characterization.mocap.synthetic_subject import (
    SyntheticTake,
    SynthOptions,
    take_of_motion,
    write_synthetic,
)
from characterization.mocap.take import MocapError
from hp_model.atomic_io import atomic_write_text
from hp_model.closed_loop import ClosedLoop
from hp_model.domains import Domain
from hp_model.simulator import HybridSimulator


def person_motion(gait: ContactCycle, opts: SynthOptions
                  ) -> tuple[np.ndarray, np.ndarray, GaitEvents, float]:
    """Times (s, at ``opts.rate``), q (n, 12), the contact events and the mean stride time
    (s) of the gait's model walking it (module docstring)."""
    model = gait.model
    thetas = contact_gait_of(model, gait.trajectory, gait.durations).thetas()
    sim = HybridSimulator(model, ClosedLoop(model, DEGREE), thetas, np.array(GAINS))
    strides = opts.n_strides + 2
    log = sim.run(*start_state(gait.trajectory), GRAPH.domains[0], steps=2 * strides + 1,
                  duration=3.0 * strides)
    if log.fall is not None:
        raise MocapError(f"synthetic subject: the gait does not walk on its own curves: "
                         f"{log.fall.message()}")
    code = np.asarray(log.domain)

    def entered(into: Domain, frm: Domain | None = None) -> np.ndarray:
        k = np.flatnonzero((code[1:] == into.code) & (code[:-1] != into.code)
                           & (True if frm is None else code[:-1] == frm.code)) + 1
        return np.asarray(log.t[k], float)

    # per prosthesis heel strike, the human toe-off, heel strike and the prosthesis toe-off
    # after it (the events of one stride, aligned as the truth pairs them)
    later = [entered(Domain.PS, Domain.DS_P), entered(Domain.DS_H),
             entered(Domain.PNS, Domain.DS_H)]
    rows = np.array([[a, *(float(ts[ts > a][0]) if (ts > a).any() else np.nan
                           for ts in later)] for a in entered(Domain.DS_P)])
    rows = rows[np.all(np.isfinite(rows), axis=1)] if rows.size else np.zeros((0, 4))
    p_land, h_lift, h_land, p_lift = rows.T if rows.size else (np.zeros(0),) * 4
    if p_land.size < 3:
        raise MocapError("synthetic subject: the walk holds fewer than 3 prosthesis heel "
                         "strikes")
    # from the first stride's double support to the last heel strike, with a lead on each
    # side that stays inside the walk
    t0 = max(p_land[0] - opts.lead, float(log.t[0]))
    t1 = min(p_land[-1] + opts.lead, float(log.t[-1]))
    t = t0 + np.arange(int(np.floor((t1 - t0) * opts.rate)) + 1) / opts.rate
    q = np.column_stack([np.interp(t, log.t, log.q[:, j]) for j in range(model.nq)])
    none = np.full(p_land.size, np.nan)
    ev = GaitEvents(p_land=p_land, h_lift=h_lift, h_land=h_land, p_lift=p_lift,
                    p_print=none, h_print=none)
    return t, q, ev, float(np.mean(np.diff(p_land)))


#: the packaged multi-contact gait the synthetic person walks by default: the example
#: subject's rolling-foot template walk, fitted (``tests/person_reference.py``, its NOTICE
#: in the folder)
REFERENCE_PERSON_GAIT = Path(__file__).resolve().parents[1] / "data" / \
    "reference_person_gait.json"


def synthesize_person(gait_path: str | os.PathLike[str] | None, opts: SynthOptions
                      ) -> tuple[SyntheticTake, ContactCycle]:
    """The take of the model of the multi-contact gait file walking it (None: the packaged
    :data:`REFERENCE_PERSON_GAIT`), and the gait."""
    gait = load_contact_cycle(gait_path or REFERENCE_PERSON_GAIT)
    t, q, ev, stride_time = person_motion(gait, opts)
    rng = np.random.default_rng(opts.seed)
    return take_of_motion(gait.model, t, q, ev, stride_time, opts, rng, "person"), gait


def write_person(out_dir: str | os.PathLike[str], synth: SyntheticTake, gait: ContactCycle,
                 opts: SynthOptions) -> dict[str, Path]:
    """:func:`~characterization.mocap.synthetic_subject.write_synthetic`, and the gait's
    subject as ``subject.toml``."""
    import tomli_w

    paths = write_synthetic(out_dir, synth, opts)
    paths["subject"] = Path(out_dir) / "subject.toml"
    atomic_write_text(paths["subject"],
                      tomli_w.dumps(gait.model.subject.model_dump(mode="json",
                                                                  exclude_none=True)))
    return paths
