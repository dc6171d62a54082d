"""Synthetic taxel layouts with known geometry, for tests, benchmarks and examples.

A hexagonal lattice on a sector of a cylinder is developable: its exact flattening is the lattice
itself (arc length along the circumference, distance along the axis), which gives tests a
closed-form reference.
"""

from __future__ import annotations

import numpy as np

from tactile.geometry.layout import TaxelLayout


def hex_lattice_mm(width_mm: float, length_mm: float, pitch_mm: float) -> np.ndarray:
    """Points of a hexagonal lattice filling a rectangle, centred on the origin.

    Returns
    -------
    points : (K, 2) float, mm — columns (s, z): s across (width), z along (length).
    """
    row_step = pitch_mm * np.sqrt(3.0) / 2.0
    n_rows = int(np.floor(width_mm / row_step)) + 1
    rows = []
    for i in range(n_rows):
        offset = 0.5 * pitch_mm * (i % 2)
        z = np.arange(offset, length_mm + 1e-9, pitch_mm)
        rows.append(np.column_stack([np.full_like(z, i * row_step), z]))
    pts = np.concatenate(rows)
    return pts - pts.mean(axis=0)


def lattice_with_n_points(width_mm: float, length_mm: float, n_points: int) -> np.ndarray:
    """A hexagonal lattice in the rectangle with exactly ``n_points`` points, (n_points, 2) mm.

    The pitch is the largest (in 0.1 % steps) that gives at least ``n_points``; the surplus
    points are those nearest the rectangle's corners (largest normalised Chebyshev distance).
    """
    pitch = np.sqrt(2.0 * width_mm * length_mm / (np.sqrt(3.0) * n_points))
    while len(pts := hex_lattice_mm(width_mm, length_mm, pitch)) < n_points:
        pitch *= 0.999
    corner = np.maximum(np.abs(pts[:, 0]) / width_mm, np.abs(pts[:, 1]) / length_mm)
    corner = corner + 1e-6 * np.hypot(pts[:, 0] / width_mm, pts[:, 1] / length_mm)
    keep = np.sort(np.argsort(corner, kind="stable")[:n_points])
    return pts[keep]


def cylinder_sector_layout(
    radius_m: float = 0.075,
    width_mm: float = 247.0,
    length_mm: float = 362.0,
    pitch_mm: float | None = None,
    *,
    n_taxels: int = 768,
    noise_m: float = 0.0,
    seed: int = 0,
    name: str = "cylinder_sector",
) -> tuple[TaxelLayout, np.ndarray]:
    """A hexagonal taxel lattice wrapped onto a cylinder sector (axis along y).

    The lattice is laid out flat with arc length ``s`` across and ``z`` along, then wrapped:
    angle = s / radius. By default it holds exactly ``n_taxels`` = 768 taxels (pitch about
    11.6 mm) on a 247 × 362 mm area, like the seed paper's Baxter forearm; give ``pitch_mm`` to
    fill the rectangle at that pitch instead (then ``n_taxels`` is ignored).

    Returns
    -------
    layout : TaxelLayout — positions (K, 3) m, outward normals (K, 3).
    flat_mm : (K, 2) float, mm — the exact isometric flattening (s, z) of each taxel.
    """
    if pitch_mm is None:
        flat_mm = lattice_with_n_points(width_mm, length_mm, n_taxels)
    else:
        flat_mm = hex_lattice_mm(width_mm, length_mm, pitch_mm)
    angle = flat_mm[:, 0] * 1e-3 / radius_m
    normals = np.column_stack([np.sin(angle), np.zeros_like(angle), np.cos(angle)])
    positions = radius_m * normals + np.column_stack(
        [np.zeros_like(angle), flat_mm[:, 1] * 1e-3, np.zeros_like(angle)]
    )
    if noise_m > 0:
        positions = positions + np.random.default_rng(seed).normal(0.0, noise_m, positions.shape)
    layout = TaxelLayout(positions_m=positions, normals=normals, name=name)
    return layout, flat_mm
