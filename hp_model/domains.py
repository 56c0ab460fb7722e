"""The domains of the walk: :class:`Domain`, the one type that names them, and the roles
their coordinates and frames play.

A domain is a member of :class:`Domain` (a :class:`~hp_model.choices.Choice`: the member is
its word in artifacts, recordings and JSON).  Everything the rest of the code needs to know
about a domain is its row of ``_SPECS`` below: the feet on the ground and how (flat, on the
heel, on the toe), its stance leg, the joints whose angles are its y2 outputs, the rows the
human's torques control.  Adding a domain is one member of :class:`Domain` and one row of
``_SPECS``; the hybrid model's constraint stacks (:mod:`hp_model.human_prosthesis`), the
FMU's tables, the gait artifact and the optimizer iterate over the domains of a graph.

    Domain.PS    prosthesis stance (the prosthesis foot flat on the ground)
    Domain.PNS   prosthesis non-stance (the human's left foot flat)
    Domain.DS_H  double support after the human's heel strike: the human foot on its heel,
                 the prosthesis foot on its toe (the prosthesis's heel off and push-off)
    Domain.DS_P  double support after the prosthesis's heel strike: the prosthesis foot on
                 its heel, the human foot on its toe
    Domain.PS_TOE   prosthesis stance on its toe (heel off), the human foot swinging
    Domain.PNS_TOE  human stance on its toe (heel off), the prosthesis swinging

A walk is a directed cycle of domains, a :class:`DomainGraph` (the guard of a domain is the
touchdown of the next domain's new contact, its impact the next domain's constraints):

    DomainGraph.PAPER         ps -> pns -> ps: the paper's two domains (flat feet, an
                              instantaneous double support)
    DomainGraph.MULTICONTACT  ps -> ps_toe -> ds_h -> pns -> pns_toe -> ds_p -> ps: the
                              single support on a flat foot, its heel off (the stance foot on
                              its toe), the other foot's heel strike, the double support
                              rolling the leading foot from heel to flat while the trailing
                              foot pushes off on its toe; the trailing toe leaves the ground
                              when the leading foot lands flat

Why this contact sequence (REFERENCE.md Sec. 5; Perry, Winter): a stance starts with the heel
strike, the foot is flat at 8-12 % of the stride and the other foot's toe-off is at 10-12 %
(nearly together: one event here), the heel rises at 30-40 % while the other leg swings and
the foot leaves on its toe at about 60 %.  Measured on openOFM's walk (tests/data): the
stance foot's pitch leaves flat about 0.1 s before the other foot's heel strike and the
leading foot is flat within 0.02-0.04 s of the trailing toe-off.  A transition is a touchdown
(the next domain's new contact lands: a rigid impact) or a lift-off (a heel leaves: no
impact, :meth:`DomainGraph.touchdown_frame` is None).

Per domain (``Domain.X.<property>``):

    stance_leg      (hip, knee, ankle) coordinates of the stance leg and its frames' side
    stance          (knee, ankle) of the stance leg: delta_p_hip = c_k th_k + c_a th_a
    y2_coords       the joints whose angles are the y2 outputs, in output order (the paper's
                    domains: 5, all but the stance ankle; a double support: both hips, the
                    leading knee and the leading sole's world pitch (``<frame>_pitch``), with
                    y1; on a toe: all 6, without y1: :mod:`hp_model.contact_outputs`)
    velocity_output whether the stacked outputs start with the hip velocity y1
    human_outputs   rows of the stacked outputs (y1, y2; in a double support then the legs'
                    squeeze) the human's 4 torques control
    next            the domain the swing foot's touchdown leads to
    code            its number (definition order: 0 = ps, 1 = pns), as logs and the FMU store it

:class:`DomainRoles` resolves them once per model into indices (``model.roles[d]``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from hp_model.choices import Choice

if TYPE_CHECKING:
    from hp_model.hybrid import HybridModel

#: the prosthesis joints (knee, ankle)
PROSTHESIS = ("th_pk", "th_pa")
#: the number of y2 outputs of a single-support domain
N_Y2 = 5


class FootPart(Choice):
    """How a foot touches the ground: flat (its sole's pose held: 3 constraints, the wrench
    F_x, F_z, M_y at the sole) or on one point (its heel or toe held in x, z: 2 constraints,
    F_x, F_z; the foot free to pitch about it)."""

    FLAT = "sole"
    HEEL = "heel"
    TOE = "toe"


@dataclass(frozen=True)
class FootContact:
    """One foot on the ground: ``side`` ("p" prosthesis, "l" human) and how."""

    side: str
    part: FootPart

    @property
    def frame(self) -> str:
        """The frame held: ``<side>_sole`` (flat), ``<side>_heel`` or ``<side>_toe``."""
        return f"{self.side}_{self.part.value}"

    @property
    def name(self) -> str:
        """Its constraint's name: ``<side>_foot`` (flat), ``<side>_heel``, ``<side>_toe``."""
        return f"{self.side}_foot" if self.part == FootPart.FLAT else self.frame

    @property
    def is_flat(self) -> bool:
        return self.part == FootPart.FLAT

    @property
    def size(self) -> int:
        """Constraint rows (and wrench entries: F_x, F_z[, M_y])."""
        return 3 if self.is_flat else 2


@dataclass(frozen=True)
class StanceLeg:
    """Coordinates of a domain's stance leg and the prefix of its frames (``side``_ankle,
    _sole, _heel, _toe)."""

    hip: str
    knee: str
    ankle: str
    side: str

    @property
    def ankle_frame(self) -> str:
        return f"{self.side}_ankle"

    @property
    def sole_frame(self) -> str:
        """The frame held flat on the ground while this leg is the stance leg."""
        return f"{self.side}_sole"


@dataclass(frozen=True)
class DomainSpec:
    """One domain's row of ``_SPECS`` (module docstring): ``contacts`` the feet on the
    ground (the stance leg's first); ``stance_leg`` the leg the phase is measured on (the
    flat foot's; in a double support the leading leg's); ``y2_coords`` the joints of its y2
    outputs, ``velocity_output`` whether it has the hip-velocity output y1 (stacked first:
    (y1, y2), else y2 alone; a double support's stack ends with the legs' squeeze: the
    leading contact's force along the ground on its curve), ``human_outputs`` the rows of that stack
    the human's four torques control."""

    contacts: tuple[FootContact, ...]
    stance_leg: StanceLeg
    y2_coords: tuple[str, ...]
    human_outputs: tuple[int, ...]
    velocity_output: bool = True


class Domain(Choice):
    """A domain of the walk (module docstring): its word, its code and its roles."""

    PS = "ps"
    PNS = "pns"
    DS_H = "ds_h"
    DS_P = "ds_p"
    PS_TOE = "ps_toe"
    PNS_TOE = "pns_toe"

    @property
    def code(self) -> int:
        """Its number (definition order), as logs and the FMU store it."""
        return _CODES[self]

    @classmethod
    def from_code(cls, code: int) -> Domain:
        """The domain numbered ``code`` (ValueError naming the valid codes otherwise)."""
        members = tuple(cls)
        if not 0 <= int(code) < len(members):
            raise ValueError(f"unknown domain code {code}; valid codes are 0..{len(members) - 1}")
        return members[int(code)]

    @property
    def spec(self) -> DomainSpec:
        return _SPECS[self]

    @property
    def stance_leg(self) -> StanceLeg:
        return _SPECS[self].stance_leg

    @property
    def stance(self) -> tuple[str, str]:
        """(knee, ankle) coordinates of the stance leg."""
        leg = _SPECS[self].stance_leg
        return leg.knee, leg.ankle

    @property
    def y2_coords(self) -> tuple[str, ...]:
        return _SPECS[self].y2_coords

    @property
    def human_outputs(self) -> tuple[int, ...]:
        return _SPECS[self].human_outputs

    @property
    def contacts(self) -> tuple[FootContact, ...]:
        return _SPECS[self].contacts

    @property
    def is_double_support(self) -> bool:
        return len(_SPECS[self].contacts) == 2

    @property
    def is_flat_stance(self) -> bool:
        """One foot on the ground, flat (the paper's domains)."""
        c = _SPECS[self].contacts
        return len(c) == 1 and c[0].is_flat

    @property
    def velocity_output(self) -> bool:
        """Whether its outputs start with the hip velocity y1 (a domain with as many
        actuators as degrees of freedom, or more: a flat foot, a double support); on a toe
        the walker pivots freely, its phase the zero dynamics."""
        return _SPECS[self].velocity_output

    @property
    def prosthesis_contact(self) -> FootContact | None:
        """The prosthesis foot's contact with the ground here (flat, heel or toe), None when
        it swings: what AMPRO3's foot switch and load cell sense."""
        return next((c for c in _SPECS[self].contacts if c.side == "p"), None)

    @property
    def is_prosthesis_stance(self) -> bool:
        """Whether the prosthesis foot is the stance foot."""
        return _SPECS[self].stance_leg.side == "p"

    def y2_row(self, coord: str) -> int:
        """The y2 row of joint ``coord`` (ValueError if it is not an output here)."""
        return _SPECS[self].y2_coords.index(coord)


#: the human's joints: on a toe its torques hold them (the double supports' rows:
#: :mod:`hp_model.contact_outputs`)
_HUMAN_JOINTS = ("th_lh", "th_lk", "th_la", "th_rh")
_P_LEG = StanceLeg("th_rh", "th_pk", "th_pa", "p")
_L_LEG = StanceLeg("th_lh", "th_lk", "th_la", "l")
_SPECS: dict[Domain, DomainSpec] = {
    Domain.PS: DomainSpec(
        contacts=(FootContact("p", FootPart.FLAT),), stance_leg=_P_LEG,
        y2_coords=("th_lh", "th_lk", "th_la", "th_rh", "th_pk"), human_outputs=(1, 2, 3, 4)),
    Domain.PNS: DomainSpec(
        contacts=(FootContact("l", FootPart.FLAT),), stance_leg=_L_LEG,
        y2_coords=("th_lh", "th_lk", "th_rh", "th_pk", "th_pa"), human_outputs=(0, 1, 2, 3)),
    Domain.DS_H: DomainSpec(
        contacts=(FootContact("l", FootPart.HEEL), FootContact("p", FootPart.TOE)),
        stance_leg=_L_LEG, y2_coords=("th_lh", "th_lk", "l_sole_pitch", "th_rh"),
        human_outputs=(1, 2, 3, 5)),
    Domain.DS_P: DomainSpec(
        contacts=(FootContact("p", FootPart.HEEL), FootContact("l", FootPart.TOE)),
        stance_leg=_P_LEG, y2_coords=("th_lh", "th_rh", "th_pk", "p_sole_pitch"),
        human_outputs=(0, 1, 2, 4)),
    Domain.PS_TOE: DomainSpec(
        contacts=(FootContact("p", FootPart.TOE),), stance_leg=_P_LEG,
        y2_coords=_HUMAN_JOINTS + PROSTHESIS, human_outputs=(0, 1, 2, 3),
        velocity_output=False),
    Domain.PNS_TOE: DomainSpec(
        contacts=(FootContact("l", FootPart.TOE),), stance_leg=_L_LEG,
        y2_coords=_HUMAN_JOINTS + PROSTHESIS, human_outputs=(0, 1, 2, 3),
        velocity_output=False),
}
_CODES: dict[Domain, int] = {d: i for i, d in enumerate(Domain)}


class DomainGraph(Choice):
    """A walk's directed cycle of domains (module docstring): its word names it in gait
    artifacts, recordings and on the command line (``--domains``)."""

    PAPER = "paper"
    MULTICONTACT = "multicontact"

    @property
    def domains(self) -> tuple[Domain, ...]:
        """The cycle's domains in walking order, starting with the prosthesis stance."""
        return _CYCLES[self]

    def next(self, domain: Domain | str) -> Domain:
        """The domain that ``domain``'s guard leads to (ValueError if it is not in the cycle)."""
        cycle = _CYCLES[self]
        d = Domain(domain)
        if d not in cycle:
            raise ValueError(f"domain {d} is not in the {self} graph ({', '.join(cycle)})")
        return cycle[(cycle.index(d) + 1) % len(cycle)]

    @property
    def step_starts(self) -> tuple[Domain, ...]:
        """The domains a step begins in: entered by a foot's touchdown that starts its
        stance (the paper's: both; the multi-contact graph's: the double supports, entered
        by a heel strike)."""
        return tuple(d for d in _CYCLES[self] if self == DomainGraph.PAPER
                     or d.is_double_support)

    def _landing(self, domain: Domain) -> FootContact | None:
        """The next domain's new contact (its foot lands in ``domain``), None where the next
        domain adds none (a heel's lift-off)."""
        before = {c.side: c for c in domain.contacts}
        for c in self.next(domain).contacts:
            held = before.get(c.side)
            if held == c or (held is not None and held.is_flat):
                continue  # held, or a flat foot rolling onto its toe
            return c
        return None

    def touchdown_frame(self, domain: Domain | str) -> str | None:
        """The frame whose touchdown is ``domain``'s guard: the next domain's new contact
        (a foot landing flat from its heel touches down with its toe); None where the next
        domain adds no contact (a heel's lift-off: no impact)."""
        d = Domain(domain)
        c = self._landing(d)
        if c is None:
            return None
        held = {h.side: h for h in d.contacts}.get(c.side)
        if c.is_flat and held is not None and held.part == FootPart.HEEL:
            return f"{c.side}_{FootPart.TOE.value}"
        return c.frame

    def guard_from_entry(self, domain: Domain | str) -> bool:
        """Whether ``domain``'s touchdown guard is armed from its entry: its landing foot was
        already in the air through the domain before and is still (the toe domains, entered
        at the other foot's heel-off, late in the swing).  Elsewhere the guard waits for
        ``SimOptions.guard_tau_min``: a foot that has just left the ground (a swing's start)
        or one landing flat from its heel."""
        d = Domain(domain)
        landing = self._landing(d)
        if landing is None:
            return False
        previous = _CYCLES[self][_CYCLES[self].index(d) - 1]
        return all(c.side != landing.side for c in previous.contacts + d.contacts)

_CYCLES: dict[DomainGraph, tuple[Domain, ...]] = {
    DomainGraph.PAPER: (Domain.PS, Domain.PNS),
    DomainGraph.MULTICONTACT: (Domain.PS, Domain.PS_TOE, Domain.DS_H, Domain.PNS,
                               Domain.PNS_TOE, Domain.DS_P),
}
#: the paper's domains, in walking order: what the consumers that run the paper's graph only
#: (the controllers' HZD outputs, the FMU, playback) iterate over
PAPER_DOMAINS = DomainGraph.PAPER.domains

@dataclass(frozen=True)
class DomainRoles:
    """One domain's roles resolved to indices of a model (coordinates, frames, output rows).

    ``knee``/``ankle``: coordinate indices of the stance knee and ankle; ``y2``: coordinate
    indices of the y2 outputs (``Domain.y2_coords`` order); ``on_outputs``: coordinate
    indices of the y2 joints that are neither the stance knee nor a prosthesis joint (the
    human joints a placement puts on their outputs, :mod:`hp_model.placement`) and
    ``on_outputs_rows`` their y2 rows; ``prosthesis``: coordinate indices of (th_pk, th_pa);
    ``prosthesis_rows``: their y2 rows (-1 where the joint is not an output: the stance ankle);
    ``human_rows``: rows of (y1, y2) the human's torques control; ``stance_foot`` and
    ``swing_foot``: the frames (heel, toe) of the stance and the swing foot."""

    name: Domain
    code: int
    next: Domain
    stance_frame: str
    swing_frame: str
    stance_frame_index: int
    swing_frame_index: int
    knee: int
    ankle: int
    y2: tuple[int, ...]
    on_outputs: tuple[int, ...]
    on_outputs_rows: tuple[int, ...]
    prosthesis: tuple[int, int]
    prosthesis_rows: tuple[int, int]
    human_rows: tuple[int, ...]
    stance_foot: tuple[str, str]
    swing_foot: tuple[str, str]


def domain_roles(model: HybridModel, domain: str) -> DomainRoles:
    """The roles of ``domain`` in ``model`` (built once per model: ``model.roles``)."""
    d = Domain(domain)
    idx = model.coord_names.index
    dom = model.domains[d]
    if dom.next is None or dom.swing_frame is None:
        raise ValueError(f"domain '{d}' has no swing frame or next domain")
    names = d.y2_coords
    knee, ankle = d.stance
    rows = tuple(r for r, n in enumerate(names) if n != knee and n not in PROSTHESIS)
    stance = model.stance_frame(d)
    nxt = Domain(dom.next)
    prosthesis_rows = tuple(d.y2_row(n) if n in names else -1 for n in PROSTHESIS)
    return DomainRoles(
        name=d, code=d.code, next=nxt, stance_frame=stance,
        swing_frame=dom.swing_frame, stance_frame_index=model.frame_index(stance),
        swing_frame_index=model.frame_index(dom.swing_frame), knee=idx(knee), ankle=idx(ankle),
        y2=tuple(idx(n) for n in names), on_outputs=tuple(idx(names[r]) for r in rows),
        on_outputs_rows=rows, prosthesis=(idx(PROSTHESIS[0]), idx(PROSTHESIS[1])),
        prosthesis_rows=(prosthesis_rows[0], prosthesis_rows[1]),
        human_rows=d.human_outputs,
        stance_foot=_heel_toe(d.stance_leg.side),
        swing_foot=_heel_toe(nxt.stance_leg.side))


def _heel_toe(side: str) -> tuple[str, str]:
    return f"{side}_heel", f"{side}_toe"
