"""A user's link mesh: refused when empty or not in metres, repaired (duplicate faces, faces on
non-manifold edges, small holes) with a line saying what, refused when too broken; a clean mesh
is used as trimesh reads it."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
import typer
from typer.testing import CliRunner

from sim.cli.parts import register
from sim.skin.link_mesh import MAX_LINK_EXTENT_M, MeshRepaired, load_link_mesh
from sim.skin.parts import load_link_mesh as part_link_mesh
from tactile.errors import ConfigError


def tube() -> trimesh.Trimesh:
    """A closed cylinder, r 0.06 m, 0.3 m long (watertight; volume pi r^2 h)."""
    return trimesh.creation.cylinder(radius=0.06, height=0.3, sections=64)


def test_a_clean_mesh_is_used_as_trimesh_reads_it(tmp_path):
    tube().export(tmp_path / "tube.stl")
    mesh, repaired = load_link_mesh(tmp_path / "tube.stl")
    assert repaired == []
    reference = trimesh.load(tmp_path / "tube.stl", force="mesh")
    np.testing.assert_array_equal(mesh.vertices, reference.vertices)
    np.testing.assert_array_equal(mesh.faces, reference.faces)


def test_a_mesh_in_millimetres_is_refused_with_its_extent_in_metres(tmp_path):
    mm = tube()
    mm.apply_scale(1000.0)
    mm.export(tmp_path / "mm.stl")
    with pytest.raises(ConfigError, match=r"spans 120 x 120 x 300 m.*likely millimetres") as err:
        load_link_mesh(tmp_path / "mm.stl")
    assert "(0.12 x 0.12 x 0.3 m)" in str(err.value) and f"({MAX_LINK_EXTENT_M:g} m)" in str(
        err.value
    )


def test_an_empty_or_unreadable_file_is_refused(tmp_path):
    (tmp_path / "empty.stl").write_text("solid nothing\nendsolid nothing\n")
    with pytest.raises(ConfigError, match="no triangles"):
        load_link_mesh(tmp_path / "empty.stl")
    with pytest.raises(ConfigError, match=r"must be \.stl or \.obj"):
        load_link_mesh(tmp_path / "link.ply")


def test_cad_defects_are_repaired_and_said(tmp_path):
    """Duplicate faces and a small hole (two faces cut out) are repaired; the result is closed
    again and holds the tube's volume (pi r^2 h, the closed-form reference)."""
    good = tube()
    faces = good.faces[2:]  # two neighbouring side faces cut out: a hole of four edges
    broken = trimesh.Trimesh(good.vertices, np.vstack([faces, faces[:3]]), process=False)
    assert not broken.is_watertight
    broken.export(tmp_path / "cad.stl")
    mesh, repaired = load_link_mesh(tmp_path / "cad.stl")
    assert repaired == ["3 duplicate faces removed", "2 faces added to close holes of <= 30 edges"]
    assert mesh.is_watertight
    assert mesh.volume == pytest.approx(np.pi * 0.06**2 * 0.3, rel=0.01)
    with pytest.warns(MeshRepaired, match=r"cad.stl repaired: 3 duplicate faces removed, 2 faces"):
        part_link_mesh(tmp_path / "cad.stl")


def test_a_mesh_too_broken_to_repair_is_refused(tmp_path):
    good = tube()
    doubled = trimesh.Trimesh(good.vertices, np.vstack([good.faces, good.faces]), process=False)
    doubled.export(tmp_path / "doubled.stl")
    with pytest.raises(ConfigError, match=r"too broken to repair safely.*Fix: repair it in CAD"):
        load_link_mesh(tmp_path / "doubled.stl")


def test_the_part_command_prints_what_was_repaired(shared_data):
    app = typer.Typer()
    register(app)
    res = CliRunner().invoke(
        app, ["part", "--mesh", str(shared_data / "baxter" / "upper_forearm_W0.STL")]
    )
    assert res.exit_code == 0, res.output
    assert "warning: link mesh" in res.output and "19 faces on non-manifold edges" in res.output
    assert "768 taxels" in res.output
