"""Procedural link meshes (trimesh, metres): a Baxter-style forearm, a gripper body, a flat plate.

The forearm is a tapered tube of superellipse (rounded-square) cross-section closed by a flat base
and an elliptical dome, with the proportions of Baxter's upper forearm W0 (about 0.16 × 0.15 ×
0.34 m; the real W0 mesh is only the shape reference, nothing is copied). All three shapes are
convex, so MuJoCo's convex-hull collision geometry equals the visual mesh the taxels lie on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh


@dataclass(frozen=True)
class ForearmShape:
    """Dimensions of the procedural forearm (m). Defaults from the W0 bounding box and sections."""

    length_m: float = 0.34  # W0 spans 0.342 m along its axis
    width_m: float = 0.150  # x across at the base (W0 body ≈ 0.145–0.158 m)
    depth_m: float = 0.145  # y across at the base (W0 ≈ 0.148 m)
    taper: float = 0.90  # cross-section scale at the top of the straight part
    dome_m: float = 0.06  # height of the rounded top cap
    squareness: float = 4.0  # superellipse exponent: 2 = ellipse, large = rectangle
    n_theta: int = 80  # vertices per ring
    n_tube: int = 24  # rings along the straight part (straight lines: few suffice)
    n_dome: int = 10  # rings on the dome


def superellipse(theta: np.ndarray, a: float, b: float, n: float) -> np.ndarray:
    """Points (K, 2) of |x/a|^n + |y/b|^n = 1 at parameter angles theta (K,) rad."""
    c, s = np.cos(theta), np.sin(theta)
    x = a * np.sign(c) * np.abs(c) ** (2.0 / n)
    y = b * np.sign(s) * np.abs(s) ** (2.0 / n)
    return np.column_stack([x, y])


def forearm_profile(shape: ForearmShape) -> tuple[np.ndarray, np.ndarray]:
    """Ring heights z (R,) m and cross-section scales (R,) along the axis, bottom to top."""
    straight = shape.length_m - shape.dome_m
    z_tube = np.linspace(0.0, straight, shape.n_tube)
    scale_tube = 1.0 + (shape.taper - 1.0) * z_tube / straight
    phi = np.linspace(0.0, 0.5 * np.pi, shape.n_dome + 1)[1:-1]
    z_dome = straight + shape.dome_m * np.sin(phi)
    scale_dome = shape.taper * np.cos(phi)
    return np.concatenate([z_tube, z_dome]), np.concatenate([scale_tube, scale_dome])


def ring_mesh(rings: np.ndarray, bottom: np.ndarray, top: np.ndarray) -> trimesh.Trimesh:
    """Close a stack of rings (R, K, 3) with a bottom and a top vertex into a watertight mesh."""
    n_r, k, _ = rings.shape
    verts = np.concatenate([rings.reshape(-1, 3), bottom[None], top[None]])
    i, j = np.meshgrid(np.arange(n_r - 1), np.arange(k), indexing="ij")
    a, b = i * k + j, i * k + (j + 1) % k
    c, d = a + k, b + k
    faces = [np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)]
    jj = np.arange(k)
    faces.append(np.column_stack([np.full(k, n_r * k), (jj + 1) % k, jj]))
    top_ring = (n_r - 1) * k
    faces.append(np.column_stack([np.full(k, n_r * k + 1), top_ring + jj, top_ring + (jj + 1) % k]))
    mesh = trimesh.Trimesh(verts, np.concatenate(faces), process=True)
    mesh.fix_normals()
    return mesh


def forearm_mesh(shape: ForearmShape | None = None) -> trimesh.Trimesh:
    """The Baxter-style forearm: axis +z from the base (z = 0) to the dome top (z = length)."""
    shape = shape or ForearmShape()
    z, scale = forearm_profile(shape)
    theta = np.linspace(0.0, 2 * np.pi, shape.n_theta, endpoint=False)
    section = superellipse(theta, shape.width_m / 2, shape.depth_m / 2, shape.squareness)
    rings = np.concatenate(
        [
            section[None] * scale[:, None, None],
            np.broadcast_to(z[:, None, None], (len(z), len(theta), 1)),
        ],
        axis=2,
    )
    return ring_mesh(rings, np.zeros(3), np.array([0.0, 0.0, shape.length_m]))


def rounded_box_mesh(
    size_m: tuple[float, float, float], radius_m: float, subdivisions: int = 3
) -> trimesh.Trimesh:
    """A box of full extents size_m (m) with edges and corners rounded by radius_m, centred at 0.

    Built as the convex hull of eight corner spheres, so faces are exactly flat.
    """
    half = np.asarray(size_m, dtype=float) / 2 - radius_m
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius_m)
    corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T * half
    points = (sphere.vertices[None] + corners[:, None]).reshape(-1, 3)
    return trimesh.convex.convex_hull(points)


def plate_mesh(size_m: tuple[float, float, float] = (0.2, 0.2, 0.01)) -> trimesh.Trimesh:
    """A flat box, top face at z = 0 (centred in x, y), for closed-form tests."""
    box = trimesh.creation.box(extents=size_m)
    box.apply_translation([0.0, 0.0, -size_m[2] / 2])
    return box
