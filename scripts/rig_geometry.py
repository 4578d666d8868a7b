"""Geometry shared by the scripts that write the rig files of data/rigs/."""

import math


def quat_wxyz_from_matrix(m):
    """Unit quaternion (w, x, y, z), w >= 0, of the rotation matrix m (rows)."""
    tr = m[0][0] + m[1][1] + m[2][2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        return [0.25 * s, (m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s]
    i = max(range(3), key=lambda k: m[k][k])
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1.0 + m[i][i] - m[j][j] - m[k][k]) * 2
    q = [0.0] * 4
    q[0] = (m[k][j] - m[j][k]) / s
    q[1 + i] = 0.25 * s
    q[1 + j] = (m[j][i] + m[i][j]) / s
    q[1 + k] = (m[k][i] + m[i][k]) / s
    if q[0] < 0:
        q = [-v for v in q]
    return q


def clean(v):
    """Rounded to 12 decimals, values below 1e-12 written as 0."""
    return [0.0 if abs(a) < 1e-12 else round(a, 12) for a in v]
