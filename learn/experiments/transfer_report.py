"""The report of Test C (``learn.experiments.transfer_lib``): Tables 15 and 16 beside the paper's
(unknown to us), confusion matrices, the learning curve as a table and a chart, and
``run_transfer``, which runs every task and writes the folder.

    res = run_transfer("data/forearm", "data/ee", "data/ee_synthetic", "out", TransferSettings())
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from learn.experiments.report import Report, markdown_table
from learn.experiments.transfer_lib import (
    AT_SCALE,
    TransferSettings,
    drop_epoch,
    model_config,
    transfer_task,
)

#: Segmentation scores of Tables 8, 15 and 16: (metric key, header).
SEG_KEYS = (
    ("pixel_accuracy", "Acc"),
    ("mean_accuracy", "mAcc"),
    ("mean_iou", "mIoU"),
    ("fw_iou", "fwIoU"),
)
ZERO_SHOT = {
    "forearm": "forearm model (source part)",
    "synthetic EE": "synthetic end-effector model (generator)",
    AT_SCALE: "forearm model at its scale (canvas)",
}


def _pct(value: float) -> float:
    return 100.0 * float(value)


def scores_table(task: str, rows: list[tuple[str, dict]]) -> str:
    """Our scores (%) beside the paper's (unknown to us) in Table 15 / 16 layout."""
    if task == "classify":
        head = ["model", "accuracy % (ours)", "accuracy % (paper)"]
        return markdown_table(head, [[n, _pct(r["metrics"]["accuracy"]), None] for n, r in rows])
    head = [
        "model",
        *(f"{h} % (ours)" for _, h in SEG_KEYS),
        *(f"{h} % (paper)" for _, h in SEG_KEYS),
    ]
    body = [[n, *(_pct(r["metrics"][k]) for k, _ in SEG_KEYS), *([None] * 4)] for n, r in rows]
    return markdown_table(head, body)


def confusions(rows: list[tuple[str, dict]], names: list[str]) -> str:
    """Confusion matrices (% of each true class) of the rows, one after the other."""
    import torch

    from learn.eval_report import confusion_markdown

    return "\n\n".join(
        f"{n}, % of each true class:\n\n" + confusion_markdown(torch.tensor(r["cm"]), tuple(names))
        for n, r in rows
    )


def curve_table(res: dict, key: str, what: str = "samples") -> str:
    """Learning curve: one row per N, one column per initialisation (score %); ``what`` the
    N counts ("samples", "hand samples")."""
    sizes = [p["n"] for p in res["curve"]["scratch"]]
    inits = list(res["curve"])  # INITS, then AT_SCALE when asked for
    body = [
        [n, *(_pct(res["curve"][i][k]["metrics"][key]) for i in inits)] for k, n in enumerate(sizes)
    ]
    return markdown_table([f"N (EE train {what})", *(f"from {i} %" for i in inits)], body)


def curve_chart(res: dict, key: str, label: str, what: str = "samples"):
    """Score % against N (log x) per initialisation, zero-shot scores as dashed lines."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4.5), layout="constrained")
    ax = fig.subplots()
    for i, (name, points) in enumerate(res["curve"].items()):
        n = [p["n"] for p in points]
        ax.plot(
            n,
            [_pct(p["metrics"][key]) for p in points],
            "os^D"[i] + "-",
            c=f"C{i}",
            label=f"fine-tuned from {name} (ours)",
        )
    for i, (name, r) in enumerate(res["zero_shot"].items()):
        ax.axhline(
            _pct(r["metrics"][key]),
            c=f"C{i + 1}",
            ls="--",
            lw=1,
            label=f"{name} model, zero-shot (ours)",
        )
    ax.set_xscale("log")
    sizes = [p["n"] for p in res["curve"]["scratch"]]
    ticks = ax.set_xticks(sizes, [str(n) for n in sizes])
    for a, b, n_a, n_b in zip(ticks, ticks[1:], sizes, sizes[1:], strict=False):
        if n_b < 1.5 * n_a:  # close on the log axis (e.g. 300 and all = 339): labels apart
            a.label1.set_horizontalalignment("right")
            b.label1.set_horizontalalignment("left")
    ax.minorticks_off()
    ax.set(
        xlabel=f"end-effector training {what} N (log scale)",
        ylabel=f"test {label}, %",
        title=f"Test C learning curve: {label} on the end-effector test split",
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return fig


def _scale_text(res: dict) -> str:
    """How the AT_SCALE rows fed the images, when there are any."""
    if "canvas_mm" not in res:
        return ""
    h, w = res["canvas_mm"]
    return (
        f' (the "at its scale" rows: each image first centred on a {h:g} × {w:g} mm '
        "canvas, the forearm map's size, so one mm is as many input pixels as on the "
        "forearm)"
    )


def write_task(rep, task: str, res: dict) -> None:
    """Tables 15 and 16, confusions and the learning curve of one task into ``rep``."""
    title = "Classification" if task == "classify" else "Segmentation"
    key, label = ("accuracy", "accuracy") if task == "classify" else ("mean_iou", "mean IoU")
    what = "samples" if task == "classify" else "hand samples"  # segmentation: hands only
    zero = [(ZERO_SHOT[k], r) for k, r in res["zero_shot"].items()]
    rep.section(
        f"{title}: zero-shot on the end-effector (paper: Table 15)",
        f"{res['n_test']} end-effector test {what}, resized to "
        f"{res['model']['input_size']} px{_scale_text(res)}.\n\n"
        + scores_table(task, zero)
        + "\n\n"
        + confusions(zero, res["class_names"]),
    )
    ft = [
        ("forearm model, fine-tuned (Test C)", res["finetuned"]),
        ("synthetic end-effector model, fine-tuned (Test C)", res["curve"]["synthetic EE"][-1]),
        ("from scratch on end-effector data (Test C schedule)", res["curve"]["scratch"][-1]),
    ]
    scaled = AT_SCALE in res["curve"]
    if scaled:
        ft.insert(
            1, ("forearm model at its scale, fine-tuned (Test C)", res["curve"][AT_SCALE][-1])
        )
    rep.section(
        f"{title}: fine-tuned on {res['n_train']} end-effector {what} (paper: Table 16)",
        scores_table(task, ft) + "\n\n" + confusions(ft[: 1 + scaled], res["class_names"]),
    )
    rep.section(f"{title}: learning curve ({label} %)", curve_table(res, key, what))
    rep.figure(
        curve_chart(res, key, label, what),
        f"curve_{task}.png",
        f"Test {label} against the number of end-effector training {what}, fine-tuned "
        f"with the Test C recipe from {len(res['curve'])} starting points; dashed: "
        "zero-shot models. The paper's Test C numbers are unknown to us, so none is drawn.",
    )


def run_transfer(
    source: str | Path,
    target: str | Path,
    pretrain: str | Path,
    out: str | Path,
    s: TransferSettings,
    *,
    classifier: str | Path | None = None,
    segmenter: str | Path | None = None,
    models_dir: str | Path | None = None,
    notes: str = "",
    config: dict | None = None,
    progress: bool = True,
) -> dict:
    """Run Test C for classification (unless ``s.classification`` is off) and segmentation (if
    asked or given); write ``out``/report.md, results.json, curve_*.png. Returns the results
    dict {task: ...}."""
    source, target, pretrain, out = Path(source), Path(target), Path(pretrain), Path(out)
    models = Path(models_dir) if models_dir else out / "models"
    tasks = {"classify": classifier} if s.classification else {}
    if s.segmentation or segmenter is not None:
        tasks["segment"] = segmenter
    for task, ckpt in tasks.items():  # checked before any work
        model_config(task, None if ckpt is None else Path(ckpt), s)
    rep = Report("transfer", out, seed=s.seed, config={**(config or {}), **dataclasses.asdict(s)})
    results = {
        task: transfer_task(
            task,
            source,
            target,
            pretrain,
            models,
            s,
            None if ckpt is None else Path(ckpt),
            progress,
        )
        for task, ckpt in tasks.items()
    }
    rep.section("Setup", notes + recipe_text(s))
    for task, res in results.items():
        write_task(rep, task, res)
    results["report"] = str(rep.write(results))
    return results


def recipe_text(s: TransferSettings) -> str:
    """How the models were trained, in words."""
    return (
        f"\n\nFine-tuning (Test C recipe): SGD, lr 0.01 halved after "
        f"{drop_epoch(s.finetune_epochs)} of {s.finetune_epochs} epochs (paper: after 60 of "
        "120), batch 128, lr × 0.1 on the first two convolutions (not from scratch), the "
        "paper's flips, no validation (the last weights are scored), the arch preset's loss. "
        "Models trained here from scratch (forearm unless given, synthetic end-effector): "
        f"the arch preset for {s.pretrain_epochs} epoch(s), "
        f"flips {'on' if s.pretrain_flips else 'off'}, best epoch on a subject-disjoint "
        "validation part. Curve subsets: nested, class-balanced random prefixes of the target's "
        "train split (subject- and instance-disjoint from its test split)."
        + (
            " SegNet trains and is scored on hand samples only (a non-hand print has no parts), "
            "so its counts are of hand samples."
            if s.segmentation
            else ""
        )
        + (
            " Every training forward pass here ran in bfloat16 autocast (weights, optimizer and "
            "loss in float32; `--precision bf16`)."
            if s.precision == "bf16"
            else ""
        )
        + (
            "\n\n**Shortened run**: fewer epochs than the paper's 120 fine-tuning and the "
            "preset's 80 training epochs; networks this briefly trained stay near chance, so "
            "these scores test the pipeline, not the method. Run without --quick (or give "
            "--classifier / --segmenter) for meaningful numbers."
            if s.finetune_epochs < 120 or s.pretrain_epochs < 80
            else ""
        )
    )
