"""`handskin generate` and `merge`: labelled synthetic datasets, resumable and sharded.

`register(app)` adds both commands (called by `sim.cli.parts.register`). The generator loads MuJoCo
(about half a second), so it is imported inside `generate_command`.
"""

from __future__ import annotations

import contextlib
import warnings
from pathlib import Path
from typing import Annotated

import typer

from sim.generate.shards import merge_shards, parse_shard
from sim.warp.options import WarpOptions
from tactile.config import to_toml
from tactile.dataset.reader import open_dataset
from tactile.errors import ConfigError, HandskinError
from tactile.files import require_output


def _fail(err: Exception) -> typer.Exit:
    typer.echo(f"error: {err}", err=True)
    return typer.Exit(2)


@contextlib.contextmanager
def echo_warnings():
    """Print each warning raised inside (e.g. a repaired link mesh) as one ``warning:`` line."""
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = lambda message, *_: typer.echo(f"warning: {message}", err=True)
        yield


TOML_KEYS = {"SkinConfig.": "episode.skin.", "EpisodeConfig.": "episode."}  # class -> TOML key


def as_flags(err: ConfigError, given: dict[str, object]) -> ConfigError:
    """``err`` with a leading ``field = value`` written as the flag the user typed
    (``chunk_size = 0 is out of range`` -> ``--chunk-size 0 is out of range``), and a nested
    dataclass's field as its TOML key (``SkinConfig.noise`` -> ``episode.skin.noise``)."""
    text = str(err)
    for name, key in TOML_KEYS.items():
        text = text.replace(name, key)
    for key, value in given.items():
        field = f"{key} = {value!r}"
        if value is not None and text.startswith(field):
            return ConfigError(f"--{key.replace('_', '-')} {value}{text[len(field) :]}")
    return ConfigError(text)


def generate_command(
    out: Annotated[
        Path,
        typer.Option(
            help="Dataset folder: new, empty, or a run of the same configuration to resume."
        ),
    ],
    part: Annotated[
        str | None,
        typer.Option(
            help="Part: forearm_paper (default), forearm, forearm_8mm, forearm_x2, forearm_x3, "
            "forearm_x4, end_effector, plate, or a link mesh .stl/.obj (m)."
        ),
    ] = None,
    n: Annotated[
        int | None,
        typer.Option("--n", help="Number of samples (count). Default: 3530, as in the paper."),
    ] = None,
    hand_fraction: Annotated[
        float | None,
        typer.Option(help="Fraction of hand samples (0..1). Default: 1710/3530, as in the paper."),
    ] = None,
    seed: Annotated[
        int | None,
        typer.Option(
            help="Dataset seed (integer >= 0); sample i depends on (seed, i). Default: 0."
        ),
    ] = None,
    split: Annotated[
        str | None,
        typer.Option(
            help="Train/test split: greedy (70/30 by samples; default) or keyed (each person's "
            "and object's side fixed by the seed and its id: datasets of one seed hold out the "
            "same people on any part and at any --n)."
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(help="Worker processes or Ray actors (count; default: all cores)."),
    ] = None,
    config: Annotated[
        Path | None,
        typer.Option(
            help="TOML file of GenerateConfig (docs/generate.md); command-line options override it."
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
            help="Samples per chunk (count), the unit of writing and resume. Default: 32."
        ),
    ] = None,
    shard: Annotated[
        str,
        typer.Option(
            help="i/n: compute only the chunks k with k mod n = i; join the shards with "
            "`handskin merge`."
        ),
    ] = "0/1",
    ray: Annotated[
        str | None,
        typer.Option(help="Run on Ray: local, auto or an address (needs the ray extra)."),
    ] = None,
    backend: Annotated[
        str | None, typer.Option(help="Simulator: mujoco (default) or warp.")
    ] = None,
    worlds: Annotated[int | None, typer.Option(help="Warp: episodes per batch (count).")] = None,
    device: Annotated[str | None, typer.Option(help="Warp device: cpu, cuda, cuda:N.")] = None,
    nconmax: Annotated[int | None, typer.Option(help="Warp: contacts per world (derived).")] = None,
    njmax: Annotated[
        int | None, typer.Option(help="Warp: constraint rows/world (derived).")
    ] = None,
    print_config: Annotated[
        bool, typer.Option("--print-config", help="Print the resolved configuration (TOML), exit.")
    ] = False,
    progress: Annotated[
        bool, typer.Option("--progress/--no-progress", help="Show a progress bar.")
    ] = True,
) -> None:
    """Generate (or resume) a labelled synthetic tactile dataset; any --workers, same bytes."""
    from sim.generate.config import load_generate_config  # start-up: mujoco
    from sim.generate.run import generate  # start-up: mujoco
    from sim.warp.run import generate as generate_on_warp  # start-up: mujoco

    flags = {"n": n, "hand_fraction": hand_fraction, "seed": seed, "split": split}
    flags |= {"chunk_size": chunk_size, "workers": workers, "backend": backend}
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
            backend=backend,
        )
        if print_config:
            typer.echo(to_toml(cfg), nl=False)
            return
        require_output(out, "--out", reads=[config], folder=True, makes="dataset")
        warp = warp_options(worlds, device, nconmax, njmax)
        with echo_warnings():  # a repaired link mesh says so
            if cfg.backend == "warp" or warp is not None:
                if ray:
                    raise ConfigError(
                        "--ray runs the C backend only; drop --ray or use --backend mujoco"
                    )
                run = generate_on_warp(
                    cfg,
                    out,
                    workers=workers,
                    shard=parse_shard(shard),
                    progress=progress,
                    warp=warp,
                )
            else:
                run = generate(
                    cfg, out, workers=workers, shard=parse_shard(shard), ray=ray, progress=progress
                )
    except ConfigError as err:
        raise _fail(as_flags(err, flags)) from err
    except HandskinError as err:
        raise _fail(err) from err
    typer.echo(
        f"{run.n_computed} samples computed in {run.wall_s:.1f} s "
        f"({run.samples_per_s:.1f} samples/s); {run.n_samples} on disk; rejected episodes: "
        f"{run.rejects or 'none'}"
    )
    typer.echo(
        f"dataset: {run.dataset}"
        if run.dataset
        else f"shard {shard} written to {out}; merge the shards with `handskin merge`"
    )
    if run.dataset:
        typer.echo(split_line(run.dataset))
        blank = blank_warning(run.dataset)
        if blank:
            typer.echo(f"warning: {blank}", err=True)


def warp_options(
    worlds: int | None, device: str | None, nconmax: int | None, njmax: int | None
) -> WarpOptions | None:
    """The warp backend's options from its flags (None when none is given), checked."""
    given = {"worlds": worlds, "device": device, "nconmax": nconmax, "njmax": njmax}
    given = {k: v for k, v in given.items() if v is not None}
    return WarpOptions(**given) if given else None


def split_line(dataset: Path) -> str:
    """One line on a merged dataset's train/test split: method, samples and held-out groups."""
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


def blank_warning(dataset: Path) -> str | None:
    """Words for a dataset whose tactile images are mostly blank (no pixel above 0): its skin
    reads no press above its noise floor, or saturates; None when most images show a print."""
    with open_dataset(dataset) as ds:
        images, step = ds["image"], 256  # images read 256 at a time: memory stays flat
        blank = sum(
            int((images[i : i + step].reshape(-1, images[0].size).max(1) == 0).sum())
            for i in range(0, len(images), step)
        )
        n, floor = len(images), float(ds.attrs.get("skin_noise_floor_counts", 0.0))
    if blank * 2 <= n:
        return None
    return (
        f"{blank} of {n} tactile images are blank (no pixel above 0): the skin reads no press "
        f"above its noise floor ({floor:g} counts; a reading ends at 65535) or saturates. "
        "Fix: check episode.skin in the configuration (noise_std_counts, full_scale_pa)"
    )


def merge_command(
    shards: Annotated[
        list[Path], typer.Argument(metavar="SHARD", help="Shard folders of one configuration.")
    ],
    out: Annotated[Path, typer.Option(help="Output dataset folder (new, empty, or a shard).")],
) -> None:
    """Merge dataset shards (`generate --shard i/n`) into one dataset, equal to a single run."""

    try:
        require_output(out, "--out", folder=True, makes="dataset")  # a shard may be OUT
        path = merge_shards(shards, out)
    except HandskinError as err:
        raise _fail(err) from err
    typer.echo(f"dataset: {path}")


def register(app: typer.Typer) -> None:
    """Add `generate` and `merge` to the handskin app."""
    app.command("generate")(generate_command)
    app.command("merge")(merge_command)
