"""Write a part as MJCF assets: link mesh (STL), model, scene with a probe, layout (.npz).

Layout of ``<out>/<part>/``: ``<part>_link.stl`` (the link mesh, m), ``<part>.xml`` (the sensorized
link with its inline sensor mesh and tactile sensor), ``scene.xml`` (the link plus a
force-controlled sphere probe above the central taxel), ``<part>_layout.npz`` (the
`tactile.TaxelLayout`). Both XML files are written by `mujoco.MjSpec.to_xml` and compile alone.
"""

from __future__ import annotations

from pathlib import Path

import mujoco

from sim.episode.probe import Probe, central_taxel
from sim.episode.scene import Contactor, scene_spec
from sim.skin.parts import Part
from tactile.files import atomic_path, write_text_atomic

SCENE_PROBE = Probe("sphere", (0.015,), 0.05)


def probe_contactor(part: Part, probe: Probe = SCENE_PROBE) -> Contactor:
    """A probe contactor 0.2 mm above the part's central taxel, pressing along its normal."""
    taxel = central_taxel(part)
    start = part.layout.positions_m[taxel] + part.layout.normals[taxel] * (probe.height_m + 2e-4)
    return Contactor(
        "probe",
        probe.shape,
        probe.size_m,
        tuple(start),
        tuple(-part.layout.normals[taxel]),
        label=1,
        mass_kg=probe.mass_kg,
    )


def _write_xml(spec: mujoco.MjSpec, path: Path) -> Path:
    spec.compile()  # raises with MuJoCo's message if the model is invalid
    write_text_atomic(path, spec.to_xml())
    return path


def write_part(part: Part, out_dir: str | Path) -> dict[str, Path]:
    """Write the part's assets under out_dir/<part.name>/; returns {kind: path}."""
    folder = Path(out_dir) / part.name
    folder.mkdir(parents=True, exist_ok=True)
    stl = folder / f"{part.name}_link.stl"
    with atomic_path(stl) as tmp:
        part.link.export(tmp, file_type="stl")
    paths = {"link": stl, "layout": folder / f"{part.name}_layout.npz"}
    part.layout.save(paths["layout"])
    for kind, contactors in (("model", ()), ("scene", (probe_contactor(part),))):
        spec = scene_spec(part, contactors, link_file=stl.name)
        spec.modelfiledir = str(folder)
        spec.modelname = part.name if kind == "model" else f"{part.name}_scene"
        name = f"{part.name}.xml" if kind == "model" else "scene.xml"
        paths[kind] = _write_xml(spec, folder / name)
    return paths
