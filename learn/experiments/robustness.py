"""`handskin experiment robustness-a` (blind spots) and `robustness-b` (lower resolution).

    run_robustness_a("data/forearm", "out/robustness-a", scale=QUICK, seed=0)
    run_robustness_b("data/forearm", "out/robustness-b", classifier="clf.pt", segmenter="seg.pt")

Both regenerate the test split's images from its raw readings through corrupted maps (Albini &
Cannata 2020, Tests A and B), run a classifier and a segmenter on them and write report.md
(tables in the layout of the paper's Tables 11-14), results.json (every confusion matrix) and
PNG charts. Networks not given are trained into ``OUT/models`` (or ``--models``) and reused.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from learn.experiments.models import DEVICE_HELP
from learn.experiments.robustness_setup import (
    FULL,
    QUICK,
    Scale,
    baseline_table,
    check_inputs,
    config_of,
    prepare,
    setup_markdown,
    timing_line,
)
from tactile.errors import HandskinError


def run_robustness_a(
    data,
    out,
    *,
    scale: Scale = FULL,
    seed: int = 0,
    classifier=None,
    segmenter=None,
    models_dir=None,
    threads: int = 2,
    progress: bool = True,
) -> Path:
    """Test A over the (N_s, r) grid of ``scale``; returns the report's path."""
    from learn.experiments.report import Report
    from learn.experiments.robustness_eval import blind_spot_study

    check_inputs(data, classifier, segmenter, threads, scale.plan.device)
    rep = Report(
        "robustness-a",
        out,
        seed=seed,
        config=config_of(data, scale, classifier, segmenter, threads),
    )
    prep = prepare(data, out, scale, seed, classifier, segmenter, models_dir, threads, progress)
    spots = [(n, r) for n in scale.n_spots for r in scale.radii_mm]
    tic = time.perf_counter()
    study = blind_spot_study(prep.frames, prep.models, spots, scale.n_patterns, seed, progress)
    prep.minutes["study"] = (time.perf_counter() - tic) / 60
    return _write_a(rep, data, scale, prep, study)


def _write_a(rep, data, scale: Scale, prep, study: dict) -> Path:
    """Tables 11-12, heat maps and results.json of a Test A study."""
    from learn.experiments import robustness_plots as P

    rep.section(
        "Setup",
        setup_markdown(data, prep.frames, prep.agreement, prep.info, scale)
        + "\n\n"
        + timing_line(prep.minutes)
        + "\n\n"
        + A_TRUTH,
    )
    rep.section(
        "Zero corruption (regenerated images)", baseline_table(study["baseline"], prep.models)
    )
    clf, seg = prep.models
    summ_c = P.spot_summaries(study, clf.name, "classify")
    summ_s = P.spot_summaries(study, seg.name, "segment")
    rep.section(
        f"Classification under blind spots (paper: Table 11) — {clf.name}",
        "Accuracy %, mean ± sd over patterns; paper: unknown.\n\n" + P.table_11(summ_c),
    )
    rep.figure(
        P.heatmaps(summ_c, ["accuracy"], f"{clf.name} accuracy"),
        "heatmap_classification.png",
        f"{clf.name} accuracy (%) over (N_s, r)",
    )
    rep.section(
        f"Segmentation under blind spots (paper: Table 12) — {seg.name}",
        "Scores %, mean ± sd over patterns.\n\n" + P.table_12(summ_s),
    )
    rep.figure(
        P.heatmaps(summ_s, P.SEG_KEYS, f"{seg.name} segmentation"),
        "heatmap_segmentation.png",
        f"{seg.name} Acc, mAcc, mIoU, fwIoU (%) over (N_s, r)",
    )
    rep.section(
        "Share of test frames a pattern changes (mean over patterns)",
        "\n".join(
            f"- N_s = {c['n_spots']}, r = {c['radius_mm']:g} mm: "
            f"{100 * sum(c['affected']) / len(c['affected']):.1f} %"
            for c in study["conditions"]
        ),
    )
    summaries = {
        "classification": {f"{n},{r:g}": s for (n, r), s in summ_c.items()},
        "segmentation": {f"{n},{r:g}": s for (n, r), s in summ_s.items()},
    }
    return rep.write(
        {
            "study": study,
            "summaries": summaries,
            "networks": prep.info,
            "minutes": prep.minutes,
            "regenerated_vs_stored": prep.agreement,
        }
    )


def run_robustness_b(
    data,
    out,
    *,
    scale: Scale = FULL,
    seed: int = 0,
    classifier=None,
    segmenter=None,
    models_dir=None,
    threads: int = 2,
    progress: bool = True,
) -> Path:
    """Test B over the removal shares of ``scale``; returns the report's path."""
    from learn.experiments.report import Report
    from learn.experiments.robustness_eval import removal_study

    check_inputs(data, classifier, segmenter, threads, scale.plan.device)
    rep = Report(
        "robustness-b",
        out,
        seed=seed,
        config=config_of(data, scale, classifier, segmenter, threads),
    )
    prep = prepare(data, out, scale, seed, classifier, segmenter, models_dir, threads, progress)
    tic = time.perf_counter()
    study = removal_study(
        prep.frames, prep.models, scale.fractions, scale.n_patterns, seed, progress
    )
    prep.minutes["study"] = (time.perf_counter() - tic) / 60
    return _write_b(rep, data, scale, prep, study)


def _write_b(rep, data, scale: Scale, prep, study: dict) -> Path:
    """Tables 13-14, curves and results.json of a Test B study."""
    from learn.experiments import robustness_plots as P
    from learn.experiments.robustness_maps import rebuilds_stored_map, rim_share

    frames = prep.frames
    same = rebuilds_stored_map(frames.tmap, frames.layout)
    rep.section(
        "Setup",
        setup_markdown(data, frames, prep.agreement, prep.info, scale)
        + "\n\n"
        + timing_line(prep.minutes)
        + "\n\n"
        + B_TRUTH
        + " Rebuilding the full layout "
        f"{'reproduces' if same else 'does NOT reproduce'} the stored map. Hand pixels in "
        f"the full map's rim: {100 * rim_share(frames.label_image, frames.tmap):.2f} %.",
    )
    clf, seg = prep.models
    curve_c = {clf.name: P.removal_summaries(study, clf.name, "classify")}
    curve_s = {seg.name: P.removal_summaries(study, seg.name, "segment")}
    rep.section("Classification with taxels removed (paper: Table 13)", P.table_13(curve_c))
    rep.figure(
        P.removal_curves(
            curve_c, ["accuracy"], "Classification, taxels removed", P.paper_removal_pct()
        ),
        "removal_classification.png",
        "Accuracy (%) against taxels removed (%); star: paper",
    )
    rep.section("Segmentation with taxels removed (paper: Table 14)", P.table_14(curve_s))
    rep.figure(
        P.removal_curves(
            curve_s, ["pixel_accuracy", "mean_iou", "p_d"], "Segmentation, taxels removed"
        ),
        "removal_segmentation.png",
        "Acc, mIoU and p_d (%) against taxels removed (%)",
    )
    return rep.write(
        {
            "study": study,
            "networks": prep.info,
            "minutes": prep.minutes,
            "regenerated_vs_stored": prep.agreement,
            "rebuilds_stored_map": same,
            "curves": {**curve_c, **curve_s},
        }
    )


A_TRUTH = (
    "Ground truth under blind spots: the label image of the faulty frame (background where its "
    "image is dark), with every pixel whose centre lies within r of a spot centre (on the map, "
    "mm) set to background. A frame none of whose pressed taxels is blind gives the same image, "
    "so only the frames a pattern changes are run again."
)
B_TRUTH = (
    "Maps are rebuilt with `TactileMap.build(layout.subset(kept), step_mm)` (the dataset stores "
    "the layout and step, not build options; the generator uses the defaults). Ground truth: "
    "each rebuilt-map pixel is traced back through its triangle's kept taxels (barycentric) to "
    "the full map and takes the full-resolution label image there; pixels outside the rebuilt "
    "map's coverage are discarded (not counted). p_d = share of ground-truth hand pixels inside "
    "the full map's mesh that the kept taxels' triangles no longer cover; the image's dilation "
    "reaches a few pixels past the mesh, and hand pixels in that rim are counted in neither "
    "(nor at 0 %, the dataset's own map)."
)


def _opt(kind, help_text: str, *names: str):
    return Annotated[kind, typer.Option(*names, help=help_text)]


OutOpt = _opt(
    Path,
    "Output folder: report.md, results.json, PNG charts (and models/ when "
    "networks are trained here).",
)
DataOpt = _opt(Path, "Dataset folder (holding dataset.h5); its test split is corrupted.")
QuickOpt = _opt(
    bool,
    "Small run (minutes): 2 patterns per condition, 300 test samples "
    "classified, 40 hand samples segmented; missing networks trained 2 epochs "
    "(HandsNet on the whole train part, SegNet on 600 train samples).",
)
SeedOpt = _opt(int, "Seed of every random draw: patterns, subsets, training (integer).")
ClfOpt = _opt(
    Path | None,
    "Classifier checkpoint (.pt file from handskin train). Default: "
    "train HandsNet here (the learn.config preset: tens of minutes on 2 cores; "
    "--quick: minutes).",
)
SegOpt = _opt(Path | None, "Segmenter checkpoint (.pt file). Default: train SegNet here.")
PatternsOpt = _opt(int | None, "Random patterns per condition (count; default 10, --quick 2).")
TestOpt = _opt(
    int | None, "Test samples classified, a fixed-seed subset (count; default all, --quick 300)."
)
SegNOpt = _opt(
    int | None, "Test hand samples segmented, a fixed-seed subset (count; default 200, --quick 40)."
)
ModelsOpt = _opt(
    Path | None,
    "Folder of networks trained here, reused when present (default: "
    "OUT/models; share it between experiments).",
)
ThreadsOpt = _opt(int, "CPU threads used by torch (count).")
DeviceOpt = _opt(str, DEVICE_HELP)
ProgressOpt = _opt(bool, "Show progress bars.")


def _command(run, name: str):
    """A typer command running ``run`` (run_robustness_a or _b) with the shared options."""

    def command(
        out: OutOpt,
        data: DataOpt,
        quick: QuickOpt = False,
        seed: SeedOpt = 0,
        classifier: ClfOpt = None,
        segmenter: SegOpt = None,
        patterns: PatternsOpt = None,
        test_samples: TestOpt = None,
        seg_samples: SegNOpt = None,
        models: ModelsOpt = None,
        threads: ThreadsOpt = 2,
        device: DeviceOpt = "cpu",
        progress: ProgressOpt = True,
    ) -> None:
        from learn.cli import _fail

        try:
            scale = (QUICK if quick else FULL).changed(patterns, test_samples, seg_samples, device)
            path = run(
                data,
                out,
                scale=scale,
                seed=seed,
                classifier=classifier,
                segmenter=segmenter,
                models_dir=models,
                threads=threads,
                progress=progress,
            )
        except (HandskinError, KeyError) as err:
            raise _fail(err) from err
        typer.echo(f"report written to {path}")

    command.__doc__ = name
    return command


def register(app: typer.Typer) -> None:
    """Add `robustness-a` and `robustness-b` to `handskin experiment`."""
    from learn.cli import _needs_torch

    app.command("robustness-a")(
        _needs_torch(
            _command(
                run_robustness_a,
                (
                    "Test A: blind spots (N_s = 1-4, r = 10-40 mm, random patterns) on the test "
                    "split; HandsNet accuracy and SegNet Acc/mAcc/mIoU/fwIoU as the paper's "
                    "Tables 11-12, heat maps over (N_s, r)."
                ),
            )
        )
    )
    app.command("robustness-b")(
        _needs_torch(
            _command(
                run_robustness_b,
                (
                    "Test B: 10-70 % of the taxels removed (nested, map rebuilt) on the test "
                    "split; accuracy and segmentation scores with p_d as the paper's Tables 13-14, "
                    "curves with spread."
                ),
            )
        )
    )
