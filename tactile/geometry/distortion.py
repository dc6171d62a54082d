"""How far a flat map is from the 3D surface it flattens: areas, angles, edge lengths, flips.

All functions are pure and vectorised on arrays; `DistortionReport` is a thin frozen facade.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DistortionReport:
    """Per-triangle and per-edge distortion of a flattening.

    area_ratio : (M,) float — signed 2D area / 3D area per triangle (negative when flipped)
    angle_error_deg : (M,) float, degrees — max |2D angle - 3D angle| over the three corners
    edge_ratio : (E,) float — 2D length / 3D length per unique edge of the flat mesh
    n_flipped : number of triangles with non-positive signed 2D area
    """

    area_ratio: np.ndarray
    angle_error_deg: np.ndarray
    edge_ratio: np.ndarray
    n_flipped: int

    def summary(self) -> dict[str, float]:
        """Medians and 5th/95th percentiles of each measure, plus ``n_flipped``.

        Keys: ``{area_ratio,angle_error_deg,edge_ratio}_{median,p05,p95}``, ``edge_ratio_max_dev``
        (max |ratio - 1| over edges) and ``n_flipped``.
        """
        out: dict[str, float] = {}
        for name in ("area_ratio", "angle_error_deg", "edge_ratio"):
            values = getattr(self, name)
            values = values[np.isfinite(values)]
            if len(values) == 0:
                continue
            p05, med, p95 = np.percentile(values, [5, 50, 95])
            out.update({f"{name}_median": med, f"{name}_p05": p05, f"{name}_p95": p95})
        if len(self.edge_ratio):
            out["edge_ratio_max_dev"] = float(np.nanmax(np.abs(self.edge_ratio - 1.0)))
        out["n_flipped"] = float(self.n_flipped)
        return {k: float(v) for k, v in out.items()}


def distortion_report(xyz_mm: np.ndarray, uv_mm: np.ndarray, faces: np.ndarray) -> DistortionReport:
    """Compare a flat mesh with its 3D original.

    xyz_mm : (V, 3) float, mm — 3D position of each flat-map vertex
    uv_mm : (V, 2) float, mm. faces : (M, 3) int, counter-clockwise when not flipped.
    """
    signed = signed_areas(uv_mm, faces)
    area3 = triangle_areas(xyz_mm, faces)
    angle_error = np.abs(corner_angles(uv_mm, faces) - corner_angles(xyz_mm, faces)).max(axis=1)
    edges = unique_edges(faces)
    length3 = np.linalg.norm(xyz_mm[edges[:, 0]] - xyz_mm[edges[:, 1]], axis=1)
    length2 = np.linalg.norm(uv_mm[edges[:, 0]] - uv_mm[edges[:, 1]], axis=1)
    # A zero-area 3D triangle or zero-length 3D edge has no ratio: NaN, never a division warning.
    return DistortionReport(
        area_ratio=_ratio(signed, area3),
        angle_error_deg=np.degrees(angle_error),
        edge_ratio=_ratio(length2, length3),
        n_flipped=int((~(signed > 0)).sum()),
    )


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """num / den elementwise, NaN where den is 0."""
    out = np.full(np.shape(num), np.nan)
    np.divide(num, den, out=out, where=den > 0)
    return out


def signed_areas(uv: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Signed area (M,) of 2D triangles: positive when counter-clockwise. uv : (V, 2)."""
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    ab, ac = b - a, c - a
    return 0.5 * (ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0])


def triangle_areas(xyz: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unsigned area (M,) of 3D triangles. xyz : (V, 3)."""
    a, b, c = xyz[faces[:, 0]], xyz[faces[:, 1]], xyz[faces[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def corner_angles(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Interior angles (M, 3) in rad at each corner, from edge lengths (any dimension)."""
    out = np.empty(faces.shape)
    for j in range(3):
        o = points[faces[:, j]]
        u = points[faces[:, (j + 1) % 3]] - o
        w = points[faces[:, (j + 2) % 3]] - o
        cos = np.einsum("ij,ij->i", u, w) / (
            np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1) + 1e-300
        )
        out[:, j] = np.arccos(np.clip(cos, -1.0, 1.0))
    return out


def unique_edges(faces: np.ndarray) -> np.ndarray:
    """Unique undirected edges (E, 2) int64 of a triangle list, sorted rows."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0).astype(np.int64)
