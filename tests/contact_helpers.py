"""What the contact-detection tests share: each foot's ankle and event names in a synthetic
take's truth, and the tolerance of a detected event derived from that truth."""

from __future__ import annotations

import numpy as np

from characterization.mocap.mapping import JOINTS

#: foot -> (its ankle joint, its touchdown and lift-off event names in the truth)
FEET = {"prosthesis": ("ankle_p", "p_land", "p_lift"), "human": ("ankle_l", "h_land", "h_lift")}


def lag_frames(truth: dict, foot: str, rate: float, speed_tol: float, window: int) -> float:
    """Frames the noise-free ankle of ``foot`` spends between rest at its events and
    ``speed_tol`` (m/s), the most over the take's touchdowns and lift-offs (events closer
    than ``window`` frames to the take's ends, and the search, within ``window`` frames)."""
    joint, land, lift = FEET[foot]
    t = truth["time"]
    a = truth["joint_position"][:, list(JOINTS).index(joint)]
    fast = np.hypot(*np.gradient(a, t, axis=0).T) > speed_tol
    lags = []
    for kind in (land, lift):
        for te in truth[kind] * rate:
            k = int(np.ceil(te)) if kind == land else int(np.floor(te))
            if not window <= k < len(t) - window:
                continue
            if kind == land:
                lags.append(te - (k - window + np.flatnonzero(fast[k - window:k])[-1]))
            else:
                lags.append(k + np.flatnonzero(fast[k:k + window])[0] - te)
    return float(max(lags))
