"""`handskin experiment robustness-a` (blind spots) and `robustness-b` (taxels removed).

    run_robustness_a("data/forearm", "out/robustness-a", scale=QUICK, seed=0)
    run_robustness_b("data/forearm", "out/robustness-b", classifier="clf.pt", segmenter="seg.pt")

Both regenerate the test split's images from its raw readings through corrupted maps (Albini &
Cannata 2020, Tests A and B), run a classifier and a segmenter on them and write report.md
(tables in the layout of the paper's Tables 11-14), results.json (every confusion matrix) and
PNG charts. Networks not given are trained into ``OUT/models`` (or ``--models``) and reused.
"""

from __future__ import annotations

from pathlib import Path

from experiments import experiment
from experiments import options as O
from experiments.settings import FULL, QUICK, Scale, changed

A_TRUTH = (
    "Ground truth under blind spots: the label image of the faulty frame (background where its "
    "image is dark), with every pixel whose centre lies within r of a spot centre (on the map, "
    "mm) set to background."
)
B_TRUTH = (
    "Maps are rebuilt from the kept taxels (`TactileMap.build(layout.subset(kept), step_mm)`). "
    "Ground truth: each rebuilt-map pixel is traced back through its triangle's kept taxels "
    "(barycentric) to the full map and takes the full-resolution label image there; pixels "
    "outside the rebuilt map's coverage are not counted. p_d = share of ground-truth hand pixels "
    "inside the full map's mesh that the kept taxels' triangles no longer cover."
)
PatternsOpt = O.opt(int | None, "Random patterns per condition (count; default 10, --quick 2).")


def run_robustness_a(data, out, scale: Scale = FULL, seed: int = 0, **nets) -> Path:
    """Test A over the (N_s, r) grid of ``scale``; returns the report's path. ``nets``:
    classifier, segmenter (checkpoints; None: trained here), models_dir, threads, progress, as
    ``experiments.networks.start`` takes them."""
    # optional: torch (the learn extra)
    from experiments import tables as T
    from experiments.networks import start
    from experiments.studies import blind_spot_study

    rep, prep = start("robustness-a", data, out, scale, seed, **nets)
    spots = [(n, r) for n in scale.n_spots for r in scale.radii_mm]
    study = blind_spot_study(prep.frames, prep.models, spots, scale.n_patterns, seed, prep.progress)
    rep.section("Setup", T.setup_text(data, prep, A_TRUTH))
    rep.section(
        "Zero corruption (regenerated images)", T.baseline_table(study["baseline"], prep.models)
    )
    summaries = T.write_spots(rep, prep.models, study, charts=True)
    return rep.write({"study": study, "summaries": summaries, "networks": prep.info})


def run_robustness_b(data, out, scale: Scale = FULL, seed: int = 0, **nets) -> Path:
    """Test B over the removal shares of ``scale``; returns the report's path (``nets``: as
    :func:`run_robustness_a`'s)."""
    # optional: torch (the learn extra)
    from experiments import tables as T
    from experiments.networks import start
    from experiments.studies import removal_study

    rep, prep = start("robustness-b", data, out, scale, seed, **nets)
    study = removal_study(
        prep.frames, prep.models, scale.fractions, scale.n_patterns, seed, prep.progress
    )
    rep.section("Setup", T.setup_text(data, prep, B_TRUTH))
    curves = {m.name: T.removal_summaries(study, m.name, m.task) for m in prep.models}
    T.write_removal(rep, prep.models, curves, "")
    return rep.write({"study": study, "networks": prep.info, "curves": curves})


@experiment("robustness-a")
def robustness_a(
    dataset: O.DatasetArg,
    out: O.OutOpt,
    quick: O.QuickOpt = False,
    seed: O.SeedOpt = 0,
    classifier: O.ClassifierOpt = None,
    segmenter: O.SegmenterOpt = None,
    segmentation: O.SegmentationOpt = True,
    patterns: PatternsOpt = None,
    models: O.ModelsOpt = None,
    threads: O.ThreadsOpt = 2,
    device: O.DeviceOpt = "cpu",
    progress: O.ProgressOpt = True,
) -> Path:
    """Test A: blind spots on the test split, as the paper's Tables 11-12.

    N_s = 1-4 spots of radius r = 10-40 mm in random patterns; accuracy and Acc, mAcc, mIoU,
    fwIoU (%) over (N_s, r), with heat maps.

    --quick: 2 patterns per condition, 300 test samples classified, 40 segmented; networks not
    given trained 2 epochs (the segmenter on 600 train samples).
    """
    O.check_segmenter(segmentation, segmenter)
    scale = changed(QUICK if quick else FULL, patterns, segmentation, device)
    nets = {"classifier": classifier, "segmenter": segmenter, "models_dir": models}
    return run_robustness_a(dataset, out, scale, seed, threads=threads, progress=progress, **nets)


@experiment("robustness-b")
def robustness_b(
    dataset: O.DatasetArg,
    out: O.OutOpt,
    quick: O.QuickOpt = False,
    seed: O.SeedOpt = 0,
    classifier: O.ClassifierOpt = None,
    segmenter: O.SegmenterOpt = None,
    segmentation: O.SegmentationOpt = True,
    patterns: PatternsOpt = None,
    models: O.ModelsOpt = None,
    threads: O.ThreadsOpt = 2,
    device: O.DeviceOpt = "cpu",
    progress: O.ProgressOpt = True,
) -> Path:
    """Test B: taxels removed from the test split's skin, as the paper's Tables 13-14.

    10-70 % of the taxels removed in nested random patterns, the map rebuilt; accuracy,
    segmentation scores and p_d (%) against the share removed, with curves.

    --quick: as robustness-a's.
    """
    O.check_segmenter(segmentation, segmenter)
    scale = changed(QUICK if quick else FULL, patterns, segmentation, device)
    nets = {"classifier": classifier, "segmenter": segmenter, "models_dir": models}
    return run_robustness_b(dataset, out, scale, seed, threads=threads, progress=progress, **nets)
