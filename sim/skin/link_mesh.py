"""A user's link mesh (STL/OBJ from CAD) checked and repaired before taxels are placed on it.

    mesh, repaired = load_link_mesh("w0.stl")     # trimesh.Trimesh (m), what was repaired

Refused with the reason (ConfigError): a file that holds no triangles, and a mesh whose extent
says it is not in metres (a link longer than ``MAX_LINK_EXTENT_M`` is almost surely in mm).
Repaired with pymeshlab, each repair counted: duplicate faces removed, faces around
non-manifold edges removed, holes of up to ``SMALL_HOLE_EDGES`` edges closed (larger openings
are the design's, and the tiling bridges them). A mesh that would lose more than
``MAX_REMOVED_SHARE`` of its faces is refused instead: it needs repairing in CAD. Duplicate
vertices are merged silently, since STL stores every triangle's corners apart. Taxels sit
where they would on the mesh as read; a taxel whose closest face was removed takes the normal
of the face now closest (on Baxter's W0: 8 of 768 taxels).
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import numpy as np
import trimesh

from tactile.errors import ConfigError

MESH_SUFFIXES = (".stl", ".obj")
MAX_LINK_EXTENT_M = 3.0  # m; a robot link is 0.05-1 m long: beyond 3 m the unit is not metres
SMALL_HOLE_EDGES = 30  # boundary edges of a hole closed as a CAD export's slit or pinhole
MAX_REMOVED_SHARE = 0.05  # faces a repair may remove before the mesh is refused instead


class MeshRepaired(UserWarning):
    """A link mesh was repaired (the message says what); commands print it as one line."""


def read_mesh(path: Path) -> trimesh.Trimesh:
    """The file's triangles as they are (vertices not merged); ConfigError when unreadable."""
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ConfigError(f"link mesh {path} must be .stl or .obj")
    if not path.is_file():
        raise ConfigError(f"link mesh {path} not found")
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as err:  # trimesh's loaders raise many types on a malformed file
        raise ConfigError(f"link mesh {path}: not a readable {path.suffix} mesh ({err})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ConfigError(
            f"link mesh {path}: no triangles in it. Fix: export the link as a triangle mesh"
        )
    return mesh


def check_extent(mesh: trimesh.Trimesh, path: Path) -> None:
    """ConfigError when the mesh spans more than MAX_LINK_EXTENT_M: it is not in metres."""
    extent = np.ptp(mesh.vertices, axis=0)
    if extent.max() > MAX_LINK_EXTENT_M:
        dims = " x ".join(f"{e:.4g}" for e in extent)
        mm = " x ".join(f"{e / 1000:.3g}" for e in extent)
        raise ConfigError(
            f"link mesh {path} spans {dims} m, longer than any robot link "
            f"({MAX_LINK_EXTENT_M:g} m): its unit is likely millimetres ({mm} m). Fix: export "
            "it in metres (or scale it by 0.001)"
        )


def repair(mesh: trimesh.Trimesh, path: Path) -> tuple[trimesh.Trimesh, list[str]]:
    """The mesh with duplicate vertices merged and the repairs of the module docstring applied;
    the list says what was repaired (empty when nothing was)."""
    import pymeshlab  # start-up: pymeshlab (only a custom link mesh needs it)

    n_faces, notes = len(mesh.faces), []
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.asarray(mesh.vertices, float), np.asarray(mesh.faces)))
    ms.meshing_remove_duplicate_vertices()
    steps = (
        ("duplicate faces removed", ms.meshing_remove_duplicate_faces),
        ("faces on non-manifold edges removed", ms.meshing_repair_non_manifold_edges),
    )
    for what, step in steps:
        before = ms.current_mesh().face_number()
        step()
        if before - ms.current_mesh().face_number():
            notes.append(f"{before - ms.current_mesh().face_number()} {what}")
    removed = n_faces - ms.current_mesh().face_number()
    if removed > MAX_REMOVED_SHARE * n_faces:
        raise ConfigError(
            f"link mesh {path}: {removed} of its {n_faces} faces are duplicate, degenerate or on "
            f"non-manifold edges (over {MAX_REMOVED_SHARE:.0%}); too broken to repair safely. "
            "Fix: repair it in CAD (or MeshLab's Cleaning filters) and export it again"
        )
    notes += _close_small_holes(ms)
    out = ms.current_mesh()
    return trimesh.Trimesh(out.vertex_matrix(), out.face_matrix(), process=False), notes


def _close_small_holes(ms) -> list[str]:
    """Close holes of up to SMALL_HOLE_EDGES edges (needs a two-manifold mesh)."""
    if not ms.get_topological_measures()["is_mesh_two_manifold"]:
        return []
    before = ms.current_mesh().face_number()
    ms.meshing_close_holes(maxholesize=SMALL_HOLE_EDGES)
    added = ms.current_mesh().face_number() - before
    return [f"{added} faces added to close holes of <= {SMALL_HOLE_EDGES} edges"] if added else []


def load_link_mesh(
    path: str | PathLike[str], scale: float = 1.0
) -> tuple[trimesh.Trimesh, list[str]]:
    """The link mesh at ``path`` in metres (after ``scale``), checked and repaired; and the list
    of repairs (see the module docstring). ConfigError names the file and the fix."""
    path = Path(path)
    mesh = read_mesh(path)
    if scale != 1.0:
        mesh.apply_scale(scale)
    check_extent(mesh, path)
    repaired, notes = repair(mesh, path)
    chosen = repaired if notes else mesh  # a clean mesh is used exactly as trimesh reads it
    return trimesh.Trimesh(chosen.vertices, chosen.faces), notes
