"""Canonical orientation of flat patches and their side-by-side packing into one map.

Orientation is a rotation only (a reflection would turn the counter-clockwise faces clockwise):
the long axis (PCA) goes along +u and the remaining 180° ambiguity is fixed from the 3D
geometry, so that the same layout always gives the same map.
"""

from __future__ import annotations

import numpy as np

GAP_MM = 4.0  # free space between packed patches, mm (a few pixels at 1 mm per pixel)


def rotation(angle_rad: float) -> np.ndarray:
    """2D rotation matrix (2, 2) acting on row vectors: ``uv @ rotation(a).T``."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s], [s, c]])


def principal_angle(uv_mm: np.ndarray) -> float:
    """Angle in rad of the long (first principal) axis of points (V, 2)."""
    centred = uv_mm - uv_mm.mean(axis=0)
    eigval, eigvec = np.linalg.eigh(centred.T @ centred)
    axis = eigvec[:, np.argmax(eigval)]
    return float(np.arctan2(axis[1], axis[0]))


def u_direction_3d(uv_mm: np.ndarray, xyz_mm: np.ndarray) -> np.ndarray:
    """3D direction (3,) in which the points move as u grows (least-squares linear fit)."""
    du = uv_mm - uv_mm.mean(axis=0)
    dx = xyz_mm - xyz_mm.mean(axis=0)
    coef = np.linalg.lstsq(du, dx, rcond=None)[0]  # (2, 3): d xyz / d (u, v)
    return coef[0]


def reference_axis_3d(xyz_mm: np.ndarray) -> np.ndarray:
    """First principal axis (3,) of 3D points, signed so its largest component is positive."""
    centred = xyz_mm - xyz_mm.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    return axis * np.sign(axis[np.argmax(np.abs(axis))])


def needs_half_turn(uv_mm: np.ndarray, xyz_mm: np.ndarray) -> bool:
    """True when +u runs against the 3D reference axis (then rotate the map by 180°).

    When +u is nearly orthogonal to the 3D principal axis (|cos| < 0.3) the sign of the largest
    component of the 3D u direction decides instead.
    """
    du = u_direction_3d(uv_mm, xyz_mm)
    ref = reference_axis_3d(xyz_mm)
    cos = du @ ref / (np.linalg.norm(du) + 1e-300)
    if abs(cos) >= 0.3:
        return bool(cos < 0)
    return bool(du[np.argmax(np.abs(du))] < 0)


def canonical_patch(uv_mm: np.ndarray, xyz_mm: np.ndarray) -> np.ndarray:
    """Rotate a flat patch (V, 2) so its long axis runs along +u; returns (V, 2) mm."""
    out = (uv_mm - uv_mm.mean(axis=0)) @ rotation(-principal_angle(uv_mm)).T
    return -out if needs_half_turn(out, xyz_mm) else out


def canonical_map(uv_mm: np.ndarray, xyz_mm: np.ndarray) -> np.ndarray:
    """Quarter-turn a packed map (V, 2) so it is wider than tall and +u follows the 3D axis."""
    extent = np.ptp(uv_mm, axis=0)
    out = uv_mm @ rotation(np.pi / 2).T if extent[1] > extent[0] else uv_mm.copy()
    out = -out if needs_half_turn(out, xyz_mm) else out
    return out - out.min(axis=0)


def shelf_offsets(sizes_mm: np.ndarray, gap_mm: float = GAP_MM) -> np.ndarray:
    """Lower-left corners (P, 2) for boxes (P, 2) packed in rows (shelves), in the given order.

    The row width is chosen so the packed map is about 1.5 times wider than tall (but never
    narrower than the widest box).
    """
    padded = sizes_mm + gap_mm
    width = max(float(padded[:, 0].max()), float(np.sqrt(1.5 * np.prod(padded, axis=1).sum())))
    offsets = np.zeros((len(sizes_mm), 2))
    x = y = row_height = 0.0
    for i, (w, h) in enumerate(padded):
        if x > 0 and x + w > width:
            x, y, row_height = 0.0, y + row_height, 0.0
        offsets[i] = (x, y)
        x, row_height = x + w, max(row_height, h)
    return offsets
