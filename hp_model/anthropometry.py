"""Body-segment parameter tables (REFERENCE.md Sec. 1).

Masses and COM locations: Plagenhoef, Evans and Abdelnour 1983 (the paper's source).
Radii of gyration about the COM as a fraction of segment length: the paper used Erdmann's
table, which could not be obtained; Winter 2009 and de Leva 1996 are offered instead and the
subject config names the one used.  The head-arms-trunk (HAT) segment uses Winter's COM and
radius for every table (de Leva gives none for a lumped HAT).
"""

from __future__ import annotations

from typing import Literal

Sex = Literal["male", "female"]
RadiiTable = Literal["winter", "de_leva"]

# fraction of body mass (Plagenhoef 1983)
MASS_FRACTION: dict[str, dict[Sex, float]] = {
    "thigh": {"male": 0.1050, "female": 0.1175},
    "shank": {"male": 0.0475, "female": 0.0535},
    "foot": {"male": 0.0143, "female": 0.0133},
    # head 8.26/8.20 + trunk 46.82/45.22 + two arms 5.70/4.97 (not Plagenhoef's whole trunk)
    "hat": {"male": 0.6648, "female": 0.6336},
}

# COM distance from the proximal joint as a fraction of segment length (Plagenhoef 1983;
# HAT from the hip: Winter 2009)
COM_FRACTION: dict[str, dict[Sex, float]] = {
    "thigh": {"male": 0.433, "female": 0.428},
    "shank": {"male": 0.434, "female": 0.419},
    "foot": {"male": 0.50, "female": 0.50},
    "hat": {"male": 0.626, "female": 0.626},
}

# radius of gyration about the COM as a fraction of segment length
RADIUS_OF_GYRATION: dict[RadiiTable, dict[str, dict[Sex, float]]] = {
    "winter": {
        "thigh": {"male": 0.323, "female": 0.323},
        "shank": {"male": 0.302, "female": 0.302},
        "foot": {"male": 0.475, "female": 0.475},
        "hat": {"male": 0.496, "female": 0.496},
    },
    "de_leva": {
        "thigh": {"male": 0.329, "female": 0.369},
        "shank": {"male": 0.251, "female": 0.267},
        "foot": {"male": 0.257, "female": 0.299},
        "hat": {"male": 0.496, "female": 0.496},  # Winter: de Leva has no lumped HAT
    },
}


def segment(
    seg: str, sex: Sex, table: RadiiTable, body_mass: float, length: float
) -> tuple[float, float, float]:
    """(mass kg, COM distance from proximal joint m, inertia about COM kg m^2) of a segment.

    Example: a 75 kg male's 0.42 m thigh with Winter radii has m = 7.875 kg, I = 0.145 kg m^2.
    """
    m = MASS_FRACTION[seg][sex] * body_mass
    c = COM_FRACTION[seg][sex] * length
    rg = RADIUS_OF_GYRATION[table][seg][sex] * length
    return m, c, m * rg * rg
