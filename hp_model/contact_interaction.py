"""The human-prosthesis loop restricted to the gait's nominal human on the multi-contact graph:
what the prosthesis's motor torque does in each domain where its foot is on the ground.

The multi-contact counterpart of :mod:`hp_model.interaction` (the paper's ``ps``).  Given a
walker state (q, qd) (a controller builds it from the gait at the phase it measures, with its
own joints from its encoders) and the domain's gait parameters theta:

- the human's four torques from its feedback linearization given the prosthesis motor torque
  u_p (``hfeedback_<d>`` of :class:`hp_model.contact_outputs.ContactConstraints`, all of its
  feedback: the human holds its rows of the domain's outputs, in a double support the
  squeeze among them in ``ds_h``; the simulated person's ``hfl_<d>`` yields a share of its
  feedback where its contacts could not take it, which is not affine in u_p);
- the domain's constrained dynamics ``dyn_<d>``: the prosthesis joint accelerations and the
  wrenches of every contact on the ground (the stance foot's first: (F_x, F_z[, M_y]) per
  contact, N and N m, at the contact's frame; a flat sole's M_y about its sole frame).

Both are exactly affine in u_p:

    (qdd_pk, qdd_pa) = f + g u_p            rad/s^2; (2,), (2, 2) per motor N m
    w                = w0 + W u_p           (k,), (k, 2); k = 3 flat, 2 heel or toe, summed

Functions (:meth:`ContactInteraction.numeric`), one per prosthesis-stance domain
(:data:`STANCE_DOMAINS`):

    interaction_<d>(q, qd, theta, gains) -> f (2), g (2, 2), w0 (k), W (k, 2)

``gains`` = (eps, kp, kd) of the human's tracking.
"""

from __future__ import annotations

import casadi as ca

from hp_model.compiled import FunctionSet
from hp_model.contact_outputs import ContactConstraints
from hp_model.domains import PROSTHESIS, Domain, DomainGraph
from hp_model.human_prosthesis import HumanProsthesisModel

#: the multi-contact graph's domains with the prosthesis foot on the ground, in walking order
#: from its heel strike: its stance
STANCE_DOMAINS = (Domain.DS_P, Domain.PS, Domain.PS_TOE, Domain.DS_H)


def wrench_size(domain: Domain) -> int:
    """Rows of a domain's contact wrenches: 3 per flat foot, 2 per heel or toe."""
    return sum(c.size for c in domain.contacts)


class ContactInteraction:
    """The restricted dynamics of :data:`STANCE_DOMAINS` for one model of the multi-contact
    graph and Bezier degree (module docstring), symbolic in ``functions``."""

    def __init__(self, model: HumanProsthesisModel, degree: int) -> None:
        if model.graph != DomainGraph.MULTICONTACT:
            raise ValueError(f"the contact interaction model needs the multicontact graph, "
                             f"not {model.graph}")
        self.model, self.degree = model, degree
        q, qd = model.q, model.qd
        joints = [model.coord_names.index(c) for c in PROSTHESIS]
        gains = ca.SX.sym("gains", 3)
        u_p = ca.SX.sym("u_p", 2)
        zero = ca.DM.zeros(2)
        self.functions: dict[str, ca.Function] = {}
        for d in STANCE_DOMAINS:
            vc = ContactConstraints(model, d, degree)
            theta = ca.SX.sym("theta", vc.n_params)
            # the human's law with the whole of its feedback (the paper's: affine in u_p),
            # not the share the simulated person yields to its contacts (a bound the model
            # leaves to the QP's own contact rows)
            u_ff, u_fb, _ = vc.functions[f"hfeedback_{d}"](q, qd, theta, gains, u_p)
            u = u_ff + u_fb
            qdd, lam = model.function(f"dyn_{d}")(q, qd, u)
            acc = qdd[joints]
            w = lam[:wrench_size(d)]
            self.functions[f"interaction_{d}"] = ca.Function(
                f"interaction_{d}", [q, qd, theta, gains],
                [ca.substitute(acc, u_p, zero), ca.jacobian(acc, u_p),
                 ca.substitute(w, u_p, zero), ca.jacobian(w, u_p)],
                ["q", "qd", "theta", "gains"], ["f", "g", "w0", "W"], {"cse": True})
        self._numeric: FunctionSet | None = None

    def numeric(self) -> FunctionSet:
        """The functions compiled to C (cached on disk by source hash), through buffers."""
        if self._numeric is None:
            self._numeric = FunctionSet(list(self.functions.values()),
                                        f"{self.model.name}_contact_interaction_m{self.degree}")
        return self._numeric
