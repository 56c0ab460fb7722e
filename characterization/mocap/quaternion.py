"""Rotation matrices of unit quaternions (x, y, z, w):
``scipy.spatial.transform.Rotation.from_quat(q).as_matrix()`` for an (n, 4) array, in numpy.

Why not scipy.spatial.transform itself: importing it imports scipy.spatial, scipy.sparse and
scipy.linalg (0.4 s on the 2-core machines, against the 2 s a user waits for ``hpcosim
mocap process`` end to end), for one conversion.  The operations are those of scipy's
compiled backend for 2-D numpy input, in its order (each quaternion divided by its norm,
the sum of squares accumulated from x to w; the matrix from the products of the normalized
components), so the matrices are scipy's bit for bit on x86-64
(``tests/test_mocap_filter.py``; the gait fits downstream amplify a last-bit difference).
"""

from __future__ import annotations

import numpy as np


def quaternion_matrices(quat: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices (lab <- body) of (n, 4) quaternions, scalar last; each
    quaternion is normalized first.  A quaternion of norm zero or not finite is an error."""
    q = np.asarray(quat, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 4:
        raise ValueError(f"quaternions of shape {q.shape}: (n, 4) is needed")
    if not np.all(np.isfinite(q)):
        raise ValueError("quaternions with non-finite components")
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    norm = np.sqrt(x * x + y * y + z * z + w * w)
    if np.any(norm == 0.0):
        raise ValueError(f"quaternion {int(np.argmax(norm == 0.0))} has norm zero")
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    m = np.empty((len(q), 3, 3))
    m[:, 0, 0] = x2 - y2 - z2 + w2
    m[:, 1, 0] = 2 * (xy + zw)
    m[:, 2, 0] = 2 * (xz - yw)
    m[:, 0, 1] = 2 * (xy - zw)
    m[:, 1, 1] = -x2 + y2 - z2 + w2
    m[:, 2, 1] = 2 * (yz + xw)
    m[:, 0, 2] = 2 * (xz + yw)
    m[:, 1, 2] = 2 * (yz - xw)
    m[:, 2, 2] = -x2 - y2 + z2 + w2
    return m
