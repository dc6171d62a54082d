"""Synthetic taxel layouts with known geometry, for tests, benchmarks and examples.

A hexagonal lattice on a sector of a cylinder is developable: its exact flattening is the lattice
itself (arc length along the circumference, distance along the axis), which gives tests a
closed-form reference.
"""

from __future__ import annotations

import numpy as np

from tactile.layout import TaxelLayout


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


def cylinder_sector_layout(
    radius_m: float = 0.075,
    width_mm: float = 247.0,
    length_mm: float = 362.0,
    pitch_mm: float = 11.0,
    *,
    noise_m: float = 0.0,
    seed: int = 0,
    name: str = "cylinder_sector",
) -> tuple[TaxelLayout, np.ndarray]:
    """A hexagonal taxel lattice wrapped onto a cylinder sector (axis along y).

    The lattice is laid out flat with arc length ``s`` across and ``z`` along, then wrapped:
    angle = s / radius. With the defaults (pitch 11 mm) the patch holds about 768 taxels on a
    247 × 362 mm area, like the seed paper's Baxter forearm.

    Returns
    -------
    layout : TaxelLayout — positions (K, 3) m, outward normals (K, 3).
    flat_mm : (K, 2) float, mm — the exact isometric flattening (s, z) of each taxel.
    """
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
