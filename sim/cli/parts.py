"""`handskin part`, `probe`, `assets`: sensorized parts, their calibration and MJCF assets.

`register(app)` adds them, and `generate` and `merge` (`sim.cli.generate`), to the project's typer
app (wired in handskin/cli.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from assets import ASSETS_DIR
from sim.cli.generate import echo_warnings
from sim.cli.generate import register as register_generate
from sim.skin import DEFAULT_PART, MAP_STEP_MM
from tactile.errors import ConfigError, HandskinError, require_positive
from tactile.files import require_output, save_figure, staged
from tactile.images.tactile_map import TactileMap

# The sim modules load trimesh, MuJoCo or pyvista (0.5-2 s): they are imported inside the
# commands that need them, so that `handskin --help` stays quick.

# label: (shape, size_m). The R10 sphere's depth stays within the 2 mm layer up to 12.6 N.
PROBE_SET = {  # sized for the default skin's 10.6 mm pad pitch (taxel area ~110 mm²)
    "sphere R10 mm": ("sphere", (0.010,)),  # one taxel carries the load: saturates first
    "sphere R40 mm": ("sphere", (0.040,)),  # contact radius sqrt(2Rd) grows: more taxels
    "flat cylinder r20 mm": ("cylinder", (0.020, 0.010)),  # ~F/1260 mm²: linear, no saturation
}


def _fail(err: Exception) -> typer.Exit:
    text = err.args[0] if isinstance(err, KeyError) and err.args else err  # no repr quotes
    typer.echo(f"error: {text}", err=True)
    return typer.Exit(2)


def check_views(views: str) -> tuple[str, ...]:
    """``--views`` as a tuple of known view names; ConfigError listing them otherwise."""
    from sim.view.pictures import VIEWS  # start-up: pyvista

    names = tuple(v.strip() for v in views.split(",") if v.strip())
    unknown = [v for v in names if v not in VIEWS]
    if unknown or not names:
        raise ConfigError(f"--views {views!r}: choose from {', '.join(VIEWS)} (comma-separated)")
    return names


def part_command(
    name: Annotated[
        str,
        typer.Argument(
            metavar="NAME",
            help="Part name: forearm_paper, forearm, forearm_8mm, forearm_x2, forearm_x3, "
            "forearm_x4, end_effector or plate.",
        ),
    ] = DEFAULT_PART,
    mesh: Annotated[
        Path | None,
        typer.Option(
            help="Custom link mesh (.stl/.obj, metres); "
            "covered like Baxter W0 (see sim.skin.parts.W0_REGION)."
        ),
    ] = None,
    png: Annotated[
        Path | None, typer.Option(help="Write a 3D picture of the part and its taxels (PNG).")
    ] = None,
    map_png: Annotated[
        Path | None, typer.Option(help="Write the flat tactile map picture (PNG, mm axes).")
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(help="Write the part's MJCF, link STL and taxel layout under this folder."),
    ] = None,
    step_mm: Annotated[
        float, typer.Option(help="Tactile map grid step, mm of skin a pixel (the paper's: 0.735).")
    ] = MAP_STEP_MM,
    views: Annotated[
        str,
        typer.Option(
            help="3D views, comma-separated from +x, -x, +y "
            "(directions in the link frame, no unit)."
        ),
    ] = "+x,-x",
) -> None:
    """Build a sensorized part; print taxel count, link extents (m) and map size (mm)."""
    from sim.skin.parts import W0_REGION, W0_TILING, custom_part, get_part  # start-up: trimesh

    try:
        require_positive("--step-mm", step_mm, "mm/pixel")
        view_names = check_views(views) if png else ()
        for flag, path in (("--png", png), ("--map-png", map_png)):
            require_output(path, flag, reads=[mesh], suffixes=(".png",))
        assets = [f"{name}_link.stl", f"{name}_layout.npz", f"{name}.xml", "scene.xml"]
        derived = [out / name / f for f in assets] if out is not None else []
        require_output(out, "--out", reads=[mesh], folder=True, derived=derived)
        with echo_warnings():
            part = custom_part(mesh, W0_REGION, W0_TILING, name) if mesh else get_part(name)
        tmap = TactileMap.build(part.layout, step_mm=step_mm)
    except (HandskinError, KeyError) as err:
        raise _fail(err) from err
    ext = np.round(part.link.extents, 4)
    h, w = tmap.shape
    typer.echo(
        f"{part.name}: {part.n_taxels} taxels, {len(np.unique(part.layout.module_ids))} "
        f"modules; link extents {ext} m; map {h * step_mm:.0f} x {w * step_mm:.0f} mm"
    )
    if png:
        from sim.view.pictures import save_part_picture  # start-up: pyvista

        with staged([png]) as (tmp,):
            save_part_picture(part, tmp, view_names)
        typer.echo(f"picture: {png}")
    if map_png:
        from tactile.figures.maps import save_map_picture  # start-up: matplotlib

        typer.echo(f"map picture: {save_map_picture(tmap, map_png, title=part.name)}")
    if out:
        from sim.episode.mjcf import write_part  # start-up: mujoco

        for kind, path in write_part(part, out).items():
            typer.echo(f"{kind}: {path}")


def probe_command(
    part: Annotated[str, typer.Option(help="Part to probe at its central taxel.")] = DEFAULT_PART,
    png: Annotated[Path | None, typer.Option(help="Write the calibration chart (PNG).")] = None,
    max_force: Annotated[float, typer.Option(help="Largest indenter force, N.")] = 40.0,
    n_forces: Annotated[int, typer.Option(help="Number of forces from 0 to max-force.")] = 61,
    seed: Annotated[int, typer.Option(help="Seed of the per-taxel gains and baselines.")] = 0,
) -> None:
    """Force sweep with sphere and flat indenters: summed reading (counts) and active taxels."""
    from sim.episode.probe import Probe, calibration_curve, central_taxel  # start-up: mujoco
    from sim.skin.parts import get_part  # start-up: trimesh

    try:
        require_positive("--max-force", max_force, "N")
        if n_forces < 2:
            raise ConfigError(f"--n-forces {n_forces} is out of range; allowed >= 2")
        if seed < 0:
            raise ConfigError(f"--seed {seed} is out of range; allowed >= 0")
        require_output(png, "--png", suffixes=(".png",))
        p = get_part(part)
    except (HandskinError, KeyError) as err:
        raise _fail(err) from err
    forces = np.linspace(0.0, max_force, n_forces)
    curves = {
        label: calibration_curve(p, Probe(shape, size), forces, central_taxel(p), seed=seed)
        for label, (shape, size) in PROBE_SET.items()
    }
    for label, c in curves.items():
        err = np.abs(c["depth_m"] - c["target_depth_m"]).max() * 1e3
        typer.echo(
            f"{label}: max summed {c['summed_signal_counts'].max():.0f} counts, max active "
            f"{c['active'].max()}, first saturation at "
            f"{_first(forces, c['saturated'] > 0)} N, depth error <= {err:.3f} mm"
        )
    if png:
        from sim.skin.model import SkinConfig  # start-up: trimesh
        from sim.view.pictures import calibration_figure  # start-up: pyvista, matplotlib

        cfg = SkinConfig()
        title = (
            f"{part}, central taxel; k = {cfg.stiffness_pa_per_m:.0e} Pa/m, full scale "
            f"{cfg.full_scale_pa / 1e3:.0f} kPa, gain spread {cfg.gain_spread:.0%}, seed {seed}"
        )
        typer.echo(f"chart: {save_figure(calibration_figure(curves, title), png, dpi=90)}")


def _first(forces: np.ndarray, mask: np.ndarray) -> str:
    return f"{forces[np.argmax(mask)]:.1f}" if mask.any() else "none"


def assets_command(
    out: Annotated[
        Path | None, typer.Option(help="Output folder (default: the assets package).")
    ] = None,
) -> None:
    """Regenerate the MJCF assets of every built-in part (see assets/README.md)."""
    from sim.episode.mjcf import write_part  # start-up: mujoco
    from sim.skin.parts import PARTS, get_part  # start-up: trimesh

    try:
        require_output(out or ASSETS_DIR, "--out", folder=True)
    except HandskinError as err:
        raise _fail(err) from err
    for name in PARTS:
        for kind, path in write_part(get_part(name), out or ASSETS_DIR).items():
            typer.echo(f"{name} {kind}: {path}")


def register(app: typer.Typer) -> None:
    """Add `part`, `probe`, `assets`, `generate` and `merge` to the handskin app."""
    app.command("part")(part_command)
    app.command("probe")(probe_command)
    app.command("assets")(assets_command)
    register_generate(app)
