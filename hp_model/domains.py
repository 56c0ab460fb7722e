"""The two domains of the walk and the roles their coordinates and frames play.

``DOMAINS`` = ("ps", "pns") is the one list of domain names: prosthesis stance (the
prosthesis foot flat on the ground) and prosthesis non-stance (the human's left foot flat).
Artifacts, recordings and the FMU store these names (the FMU and the logs number them by
their index here).

Per domain, the static tables name the coordinates that play each role:

    STANCE_LEG[d]     (hip, knee, ankle) coordinates of the stance leg and its ankle frame
    STANCE[d]         (knee, ankle) of the stance leg: delta_p_hip = c_k th_k + c_a th_a
    Y2_COORDS[d]      the 5 joints whose angles are the y2 outputs, in output order
    HUMAN_OUTPUTS[d]  rows of the stacked outputs (y1, y2) the human's 4 torques control

:class:`DomainRoles` resolves them once per model into indices (``model.roles[d]``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hp_model.hybrid import HybridModel

DOMAINS: tuple[str, str] = ("ps", "pns")
#: each domain's number (its index in ``DOMAINS``: 0 = ps, 1 = pns), as logs and the FMU store it
DOMAIN_CODE = {d: i for i, d in enumerate(DOMAINS)}
#: the prosthesis joints (knee, ankle)
PROSTHESIS = ("th_pk", "th_pa")


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


STANCE_LEG = {"ps": StanceLeg("th_rh", "th_pk", "th_pa", "p"),
              "pns": StanceLeg("th_lh", "th_lk", "th_la", "l")}
STANCE = {d: (leg.knee, leg.ankle) for d, leg in STANCE_LEG.items()}
Y2_COORDS = {
    "ps": ("th_lh", "th_lk", "th_la", "th_rh", "th_pk"),
    "pns": ("th_lh", "th_lk", "th_rh", "th_pk", "th_pa"),
}
N_Y2 = 5
HUMAN_OUTPUTS = {"ps": (1, 2, 3, 4), "pns": (0, 1, 2, 3)}


def y2_row(domain: str, coord: str) -> int:
    """The y2 row of joint ``coord`` in ``domain`` (ValueError if it is not an output)."""
    return Y2_COORDS[domain].index(coord)


@dataclass(frozen=True)
class DomainRoles:
    """One domain's roles resolved to indices of a model (coordinates, frames, output rows).

    ``knee``/``ankle``: coordinate indices of the stance knee and ankle; ``y2``: coordinate
    indices of the y2 outputs (``Y2_COORDS`` order); ``on_outputs``: coordinate indices of the
    y2 joints that are neither the stance knee nor a prosthesis joint (the human joints a
    placement puts on their outputs, :mod:`hp_model.placement`) and ``on_outputs_rows`` their
    y2 rows; ``prosthesis``: coordinate indices of (th_pk, th_pa); ``prosthesis_rows``: their
    y2 rows (-1 where the joint is not an output: the stance ankle);
    ``human_rows``: rows of (y1, y2) the human's torques control; ``stance_foot`` and
    ``swing_foot``: the frames (heel, toe) of the stance and the swing foot."""

    name: str
    code: int
    next: str
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
    idx = model.coord_names.index
    dom = model.domains[domain]
    if dom.next is None or dom.swing_frame is None:
        raise ValueError(f"domain '{domain}' has no swing frame or next domain")
    names = Y2_COORDS[domain]
    knee, ankle = STANCE[domain]
    rows = tuple(r for r, n in enumerate(names) if n != knee and n not in PROSTHESIS)
    stance = model.stance_frame(domain)
    return DomainRoles(
        name=domain, code=DOMAIN_CODE[domain], next=dom.next, stance_frame=stance,
        swing_frame=dom.swing_frame, stance_frame_index=model.frame_index(stance),
        swing_frame_index=model.frame_index(dom.swing_frame), knee=idx(knee), ankle=idx(ankle),
        y2=tuple(idx(n) for n in names), on_outputs=tuple(idx(names[r]) for r in rows),
        on_outputs_rows=rows, prosthesis=(idx(PROSTHESIS[0]), idx(PROSTHESIS[1])),
        prosthesis_rows=tuple(y2_row(domain, n) if n in names else -1  # type: ignore[arg-type]
                              for n in PROSTHESIS),
        human_rows=HUMAN_OUTPUTS[domain],
        stance_foot=_heel_toe(STANCE_LEG[domain].side),
        swing_foot=_heel_toe(STANCE_LEG[dom.next].side))


def _heel_toe(side: str) -> tuple[str, str]:
    return f"{side}_heel", f"{side}_toe"
