"""`handskin part`, `probe`, `assets`, `generate`, `merge`: parts, calibration, MJCF, datasets.

`register(app)` adds the commands to the project's typer app (wired in handskin/cli.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from tactile.errors import HandskinError

# label: (shape, size_m). The R10 sphere's depth stays within the 2 mm layer up to 12.6 N.
PROBE_SET = {  # sized for the default skin's 10.6 mm pad pitch (taxel area ~110 mm²)
    "sphere R10 mm": ("sphere", (0.010,)),  # one taxel carries the load: saturates first
    "sphere R40 mm": ("sphere", (0.040,)),  # contact radius sqrt(2Rd) grows: more taxels
    "flat cylinder r20 mm": ("cylinder", (0.020, 0.010)),  # ~F/1260 mm²: linear, no saturation
}


def _fail(err: Exception) -> typer.Exit:
    typer.echo(f"error: {err}", err=True)
    return typer.Exit(2)


def part_command(
    name: Annotated[
        str,
        typer.Argument(
            help="Part name: forearm, forearm_8mm, forearm_x2, forearm_x4, end_effector or plate."
        ),
    ] = "forearm",
    mesh: Annotated[
        Path | None,
        typer.Option(
            help="Custom link mesh (.stl/.obj, metres); "
            "covered like Baxter W0 (see sim.parts.W0_REGION)."
        ),
    ] = None,
    png: Annotated[
        Path | None, typer.Option(help="Write a 3D picture of the part and its taxels (PNG).")
    ] = None,
    map_png: Annotated[
        Path | None, typer.Option(help="Write the flat tactile map picture (PNG, mm axes).")
    ] = None,
    mjcf_out: Annotated[
        Path | None, typer.Option(help="Write MJCF + STL + layout under this folder.")
    ] = None,
    step_mm: Annotated[float, typer.Option(help="Tactile map grid step, mm/pixel.")] = 1.0,
    views: Annotated[
        str,
        typer.Option(
            help="3D views, comma-separated from +x, -x, +y "
            "(directions in the link frame, no unit)."
        ),
    ] = "+x,-x",
) -> None:
    """Build a sensorized part; print taxel count, link extents (m) and map size (mm)."""
    from sim.parts import W0_REGION, W0_TILING, custom_part, get_part
    from tactile.tactile_map import TactileMap

    try:
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
        from sim.pictures import save_part_picture

        typer.echo(f"picture: {save_part_picture(part, png, tuple(views.split(',')))}")
    if map_png:
        from tactile.plot import save_map_picture

        typer.echo(f"map picture: {save_map_picture(tmap, map_png, title=part.name)}")
    if mjcf_out:
        from sim.mjcf import write_part

        for kind, path in write_part(part, mjcf_out).items():
            typer.echo(f"{kind}: {path}")


def probe_command(
    part: Annotated[str, typer.Option(help="Part to probe at its central taxel.")] = "forearm",
    png: Annotated[Path | None, typer.Option(help="Write the calibration chart (PNG).")] = None,
    max_force: Annotated[float, typer.Option(help="Largest indenter force, N.")] = 40.0,
    n_forces: Annotated[int, typer.Option(help="Number of forces from 0 to max-force.")] = 61,
    seed: Annotated[int, typer.Option(help="Seed of the per-taxel gains and baselines.")] = 0,
) -> None:
    """Force sweep with sphere and flat indenters: summed reading (counts) and active taxels."""
    from sim.parts import get_part
    from sim.probe import Probe, calibration_curve, central_taxel

    try:
        p = get_part(part)
    except KeyError as err:
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
        from sim.pictures import calibration_figure
        from sim.skin import SkinConfig

        cfg = SkinConfig()
        title = (
            f"{part}, central taxel; k = {cfg.stiffness_pa_per_m:.0e} Pa/m, full scale "
            f"{cfg.full_scale_pa / 1e3:.0f} kPa, gain spread {cfg.gain_spread:.0%}, seed {seed}"
        )
        png.parent.mkdir(parents=True, exist_ok=True)
        calibration_figure(curves, title).savefig(png, dpi=90)
        typer.echo(f"chart: {png}")


def _first(forces: np.ndarray, mask: np.ndarray) -> str:
    return f"{forces[np.argmax(mask)]:.1f}" if mask.any() else "none"


def assets_command(
    out: Annotated[
        Path | None, typer.Option(help="Output folder (default: the assets package).")
    ] = None,
) -> None:
    """Regenerate the MJCF assets of every built-in part (see assets/README.md)."""
    from assets import ASSETS_DIR
    from sim.mjcf import write_part
    from sim.parts import PARTS, get_part

    for name in PARTS:
        for kind, path in write_part(get_part(name), out or ASSETS_DIR).items():
            typer.echo(f"{name} {kind}: {path}")


def generate_command(
    out: Annotated[
        Path,
        typer.Option(
            help="Dataset folder (path): new, empty, or a run of the same configuration to resume."
        ),
    ],
    part: Annotated[
        str | None,
        typer.Option(
            help="Part: forearm, forearm_8mm, forearm_x2, forearm_x4, end_effector, plate, or a "
            "link mesh file .stl/.obj (metres). "
            "Default: forearm."
        ),
    ] = None,
    n: Annotated[
        int | None,
        typer.Option("--n", help="Number of samples (count). Default: 3530 as in the paper."),
    ] = None,
    hand_fraction: Annotated[
        float | None,
        typer.Option(help="Fraction of hand samples (unitless, 0..1). Default: 1710/3530."),
    ] = None,
    seed: Annotated[
        int | None,
        typer.Option(
            help="Dataset seed (integer >= 0); sample i depends only on (seed, i). Default: 0."
        ),
    ] = None,
    split: Annotated[
        str | None,
        typer.Option(
            help="Train/test split: greedy (70/30 by samples; default) or keyed (each subject's "
            "and object instance's side fixed by the seed and its id, so datasets of one seed "
            "on any part, of any size, hold out the same people; fractions within a few "
            "points of 70/30)."
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            help="Worker processes or Ray actors (count). Default: all cores. Never changes "
            "the bytes."
        ),
    ] = None,
    config: Annotated[
        Path | None,
        typer.Option(
            help="TOML file of GenerateConfig (docs/generate.md): scene, subjects, skin, "
            "randomization; command-line options override it."
        ),
    ] = None,
    keep_sequences: Annotated[
        bool | None,
        typer.Option(
            "--keep-sequences/--no-keep-sequences",
            help="Also store each episode's 10 Hz raw sequence (frames x taxels, counts).",
        ),
    ] = None,
    chunk_size: Annotated[
        int | None,
        typer.Option(
            help="Samples per chunk (count): the unit of atomic writes and resume. Default: 32."
        ),
    ] = None,
    shard: Annotated[
        str,
        typer.Option(
            help="i/n: compute only chunks k with k mod n = i (unitless indices); merge the shard "
            "folders with `handskin merge`."
        ),
    ] = "0/1",
    ray: Annotated[
        str | None,
        typer.Option(
            help="Run on Ray: 'local' (start a local instance), 'auto' or an address "
            "(needs the ray extra)."
        ),
    ] = None,
    print_config: Annotated[
        bool,
        typer.Option(help="Print the resolved configuration (TOML) and exit without generating."),
    ] = False,
    quiet: Annotated[bool, typer.Option(help="No progress bar.")] = False,
) -> None:
    """Generate (or resume) a labelled synthetic tactile dataset (same bytes for any --workers)."""
    from sim.gen_config import load_generate_config
    from sim.generate import generate, parse_shard
    from tactile.config import to_toml

    try:
        cfg = load_generate_config(
            config,
            part=part,
            n=n,
            hand_fraction=hand_fraction,
            seed=seed,
            split=split,
            keep_sequences=keep_sequences,
            chunk_size=chunk_size,
        )
        if print_config:
            typer.echo(to_toml(cfg), nl=False)
            return
        report = generate(
            cfg, out, workers=workers, shard=parse_shard(shard), ray=ray, progress=not quiet
        )
    except HandskinError as err:
        raise _fail(err) from err
    typer.echo(
        f"{report.n_computed} samples computed in {report.wall_s:.1f} s "
        f"({report.samples_per_s:.1f} samples/s); {report.n_samples} on disk; rejected episodes: "
        f"{report.rejects or 'none'}"
    )
    typer.echo(
        f"dataset: {report.dataset}"
        if report.dataset
        else f"shard {shard} written to {out}; merge the shards with `handskin merge`"
    )
    if report.dataset:
        typer.echo(split_line(report.dataset))


def split_line(dataset: Path) -> str:
    """One line on a merged dataset's train/test split: method, samples and held-out groups."""
    from tactile.dataset import open_dataset

    with open_dataset(dataset) as ds:
        test = ds.splits["test"]
        groups = [
            len(set(ds[f][()][test].tolist()) - {-1}) if f in ds.fields else 0
            for f in ("subject_id", "instance_id")
        ]
        method = ds.attrs.get("split_method", "greedy")
        n = len(ds)
    return (
        f"split ({method}): {n - len(test)} train / {len(test)} test samples "
        f"({100 * (n - len(test)) / max(n, 1):.1f} % train); held out: {groups[0]} subjects, "
        f"{groups[1]} object / body-part instances"
    )


def merge_command(
    shards: Annotated[list[Path], typer.Argument(help="Shard folders of one configuration.")],
    out: Annotated[Path, typer.Option(help="Output dataset folder (new, empty, or a shard).")],
) -> None:
    """Merge dataset shards (`generate --shard i/n`) into one dataset, equal to a single run."""
    from sim.generate import merge_shards

    try:
        path = merge_shards(shards, out)
    except HandskinError as err:
        raise _fail(err) from err
    typer.echo(f"dataset: {path}")


def register(app: typer.Typer) -> None:
    """Add `part`, `probe`, `assets`, `generate` and `merge` to the handskin app."""
    app.command("part")(part_command)
    app.command("probe")(probe_command)
    app.command("assets")(assets_command)
    app.command("generate")(generate_command)
    app.command("merge")(merge_command)
