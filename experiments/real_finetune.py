"""Fine-tuning a segmenter on a few real prints, the use the product is for: a network pretrained
on simulation against the same network from a random start, on k real prints of one fold,
scored on the other fold by part localisation (`learn.evaluate.real`).

    handskin experiment real-finetune --pretrained runs/segnet/best.pt \\
        --train data/real1 --test data/real2 --out reports/real-finetune

For every k (10, 30, 100, 342 by default) and draw (several for small k: a seeded subset of k
prints of the train fold), both starts train with one recipe, `handskin finetune`'s
(`learn.train.finetune`): the preset SegNet's optimiser and loss for a fixed number of steps
whatever k is, on copies of the real prints moved and turned, the same copies for both starts.
The pretrained start also replays simulated prints (``replay``) beside its real ones; the random
start trains on the real prints alone. The pretrained network with no real print (k = 0) is the
zero-shot point. Results are kept in ``results.json`` as they come: a stopped run resumes where
it stopped.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from experiments import experiment
from experiments import options as O
from learn.train.finetune import FinetuneRecipe, finetune, replay_prints, replay_source, shift_px
from tactile.dataset.boxes import BoxFolder, is_box_folder
from tactile.errors import ConfigError, DataError
from tactile.files import save_figure, write_text_atomic
from tactile.images.labels import CLASS_NAMES

STARTS = ("simulation", "random")  # pretrained on simulated prints; a random start


@dataclass(frozen=True)
class FinetunePlan(FinetuneRecipe):
    """The recipe of every run (`learn.train.finetune.FinetuneRecipe`: steps, replay, moves,
    seed, threads) and what the experiment varies: real prints per run (``ks``, count) and draws
    of each (``draws``, one per k)."""

    ks: tuple[int, ...] = (10, 30, 100, 342)
    draws: tuple[int, ...] = (3, 2, 1, 1)

    def __post_init__(self) -> None:
        if len(self.draws) != len(self.ks) or min(self.draws, default=1) < 1:
            raise ConfigError("--draws: one count >= 1 per k of --ks")
        if min(self.ks, default=1) < 1:
            raise ConfigError("--ks: counts >= 1")
        super().__post_init__()


QUICK = FinetunePlan(ks=(4, 12), draws=(2, 1), steps=6, replay=8)


def subset(n: int, k: int, draw: int, seed: int) -> np.ndarray:
    """The sorted indices of draw ``draw`` of ``k`` prints among ``n`` (all of them when k >= n),
    from ``SeedSequence([seed, k, draw])``: the same prints for both starts."""
    if k >= n:
        return np.arange(n)
    rng = np.random.default_rng(np.random.SeedSequence([seed, k, draw]))
    return np.sort(rng.choice(n, k, replace=False))


def localisation(model, run, test: BoxFolder) -> dict:
    """Part localisation of a trained network on the test fold (`learn.evaluate.real`)."""
    from learn.evaluate.real import part_localisation  # optional: torch (the learn extra)
    from learn.infer.fastpath import fast_inference
    from learn.infer.predict import Predictor

    pred = Predictor(fast_inference(model), "segment", run.model.input_size, CLASS_NAMES)
    scores, _ = part_localisation(pred, test)
    return {k: scores[k] for k in ("localised", "boxes", "box_iou", "box_iou_above_half")}


def run_finetune(
    pretrained: Path,
    train: Path,
    test: Path,
    out: Path,
    plan: FinetunePlan,
    progress: bool,
    sim: Path | None = None,
) -> dict:
    """Every (k, draw, start) run of ``plan``, resumed from ``out/results.json``; returns the
    results and writes the report, the chart and the results. ``sim``: the simulated dataset
    the pretrained start replays (default: the one it trained on)."""
    import torch  # optional: the learn extra

    from learn.data.boxes import BoxFolderDataset
    from learn.data.load import TensorData, materialize
    from learn.train.checkpoint import load_checkpoint, model_from_checkpoint, run_of

    for flag, path in (("--train", train), ("--test", test)):
        if not is_box_folder(path):
            raise DataError(f"{flag} {path}: not a box folder. Fix: handskin ingest-boxes first")
    ckpt = load_checkpoint(pretrained)
    base = run_of(ckpt, pretrained)
    if base.task != "segment":
        raise ConfigError(f"--pretrained {pretrained}: a '{base.task}' network; give a segmenter")
    train_folder, test_folder = BoxFolder.open(train), BoxFolder.open(test)
    if max(plan.ks) > len(train_folder):
        raise ConfigError(f"--ks {max(plan.ks)}: {train} holds {len(train_folder)} prints")
    sim, sim_print, sim_ds = replay_source(sim, base, plan, ckpt, f"--pretrained {pretrained}")
    results_path = out / "results.json"
    done = json.loads(results_path.read_text()) if results_path.is_file() else {"runs": []}
    key = {"pretrained": str(pretrained), "train": str(train), "test": str(test)}
    key |= {"replay_from": None if sim is None else str(sim), "replay_fingerprint": sim_print}
    key = json.loads(json.dumps(key | {"plan": dataclasses.asdict(plan)}))  # as stored
    if as_now(done.get("key", key)) != key:
        raise DataError(f"{results_path} holds another experiment. Fix: another --out folder")
    done["key"] = key
    out.mkdir(parents=True, exist_ok=True)
    replay = replay_prints(sim_ds, plan)
    torch.set_num_threads(plan.threads)
    size = base.model.input_size
    shift = shift_px(plan, train_folder.frame_px or train_folder[0].image.shape, size)
    pool = materialize(
        BoxFolderDataset(train, None, "segment", size, flips=False), "real", progress
    )
    if "zero_shot" not in done:
        model, _ = model_from_checkpoint(ckpt)
        done["zero_shot"] = localisation(model, base, test_folder)
        write_text_atomic(results_path, json.dumps(done, indent=1))
    for k, draws in zip(plan.ks, plan.draws, strict=True):
        for draw in range(min(draws, 1 if k >= len(train_folder) else draws)):
            idx = subset(len(train_folder), k, draw, plan.seed)
            for start in STARTS:
                if any(
                    r["k"] == k and r["draw"] == draw and r["start"] == start for r in done["runs"]
                ):
                    continue
                real = TensorData(pool.x[idx], pool.y[idx], pool.mirror)
                pretrained_run = start == "simulation"
                result, run, _ = finetune(
                    base,
                    real,
                    replay if pretrained_run else None,
                    shift,
                    plan,
                    init=ckpt if pretrained_run else None,
                    start=start,
                    draw=draw,
                    description={"k": k},
                    progress=progress,
                )
                row = {"k": k, "draw": draw, "start": start, "prints": idx.tolist()}
                row |= localisation(result.model, run, test_folder)
                done["runs"].append(row)
                write_text_atomic(results_path, json.dumps(done, indent=1))
    _chart(done, out / "localisation.png")
    write_text_atomic(out / "report.md", report(done, plan))
    return done


def as_now(key: dict) -> dict:
    """A stored results key with the fields results written before replay or moved copies
    lack: no replay, plain repeats."""
    key = {"replay_from": None, "replay_fingerprint": None} | key
    return key | {"plan": {"replay": 0, "shift_mm": 0.0, "turn_deg": 0.0} | key["plan"]}


def summary(done: dict) -> list[dict]:
    """Per (start, k): mean, min and max localisation over its draws."""
    rows = []
    for start in STARTS:
        for k in sorted({r["k"] for r in done["runs"]}):
            values = [r["localised"] for r in done["runs"] if r["start"] == start and r["k"] == k]
            if values:
                rows.append(
                    {
                        "start": start,
                        "k": k,
                        "draws": len(values),
                        "mean": float(np.mean(values)),
                        "min": float(min(values)),
                        "max": float(max(values)),
                    }
                )
    return rows


def report(done: dict, plan: FinetunePlan) -> str:
    """The report: the command's inputs, the zero-shot point, the table against k."""
    key = done["key"]
    words = ["handskin", "experiment", "real-finetune", "--pretrained", key["pretrained"]]
    words += ["--train", key["train"], "--test", key["test"]]
    if plan.replay != FinetunePlan.replay:
        words += ["--replay", str(plan.replay)]
    if plan.replay and key.get("replay_from") is not None:
        words += ["--replay-from", key["replay_from"]]
    for flag, value, default in (
        ("--shift-mm", plan.shift_mm, FinetunePlan.shift_mm),
        ("--turn-deg", plan.turn_deg, FinetunePlan.turn_deg),
    ):
        if value != default:
            words += [flag, f"{value:g}"]
    zero = done["zero_shot"]
    lines = [
        "# A segmenter fine-tuned on k real prints",
        "",
        f"Regenerate: `{' '.join(words)} --out OUT` (plan: {json.dumps(key['plan'])}).",
        "",
        "Part localisation on the test fold's boxes (box-derived labels: each contact pixel in "
        "its smallest box; a box is localised when the segmenter's majority class over its "
        "pixels is the box's part; chance about 1 in 6). Trained on k prints of the train fold "
        f"for {plan.steps} steps with the preset SegNet recipe, from the simulation-pretrained "
        "network"
        + (f" (replaying {plan.replay} simulated prints beside them)" if plan.replay else "")
        + " and from a random start on the real prints alone, on the same draws"
        + (
            f"; copies of the real prints moved up to {plan.shift_mm:g} mm and turned up to "
            f"{plan.turn_deg:g} deg, the same for both starts."
            if plan.moves
            else "."
        ),
        "",
        f"Zero-shot (the pretrained network, no real print): {100 * zero['localised']:.1f} % of "
        f"{zero['boxes']} boxes.",
        "",
        "| k real prints | draws | simulation-pretrained: mean % [min, max] | random start: mean "
        "% [min, max] |",
        "|---|---|---|---|",
    ]
    table = {(r["start"], r["k"]): r for r in summary(done)}
    for k in sorted({r["k"] for r in done["runs"]}):
        cells = []
        for start in STARTS:
            r = table.get((start, k))
            cells.append(
                "–"
                if r is None
                else f"{100 * r['mean']:.1f} [{100 * r['min']:.1f}, {100 * r['max']:.1f}]"
            )
        draws = table.get(("simulation", k), {}).get("draws", 0)
        lines.append(f"| {k} | {draws} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines) + "\n\n![localisation against k](localisation.png)\n"


def _chart(done: dict, png: Path) -> Path:
    from matplotlib.figure import Figure  # start-up: matplotlib

    fig = Figure(figsize=(7, 4.5), layout="constrained")
    ax = fig.subplots()
    rows = summary(done)
    for start, colour in zip(STARTS, ("#c0392b", "#2471a3"), strict=True):
        mine = [r for r in rows if r["start"] == start]
        k = np.array([r["k"] for r in mine])
        mean = np.array([100 * r["mean"] for r in mine])
        spread = np.array(
            [[100 * (r["mean"] - r["min"]), 100 * (r["max"] - r["mean"])] for r in mine]
        ).T
        replay = done["key"]["plan"].get("replay", 0)
        label = "random start, real prints alone"
        if start == "simulation":
            label = "pretrained on simulation" + (f", {replay} replayed" if replay else "")
        ax.errorbar(k, mean, yerr=spread, marker="o", capsize=3, color=colour, label=label)
    ax.axhline(
        100 * done["zero_shot"]["localised"],
        color="#c0392b",
        ls=":",
        label="pretrained, no real print",
    )
    ax.axhline(100 / 6, color="0.5", ls="--", label="chance (1 in 6)")
    ax.set_xscale("log")
    ax.set_xlabel("real prints fine-tuned on (k)")
    ax.set_ylabel("boxes localised on the other fold, %")
    ax.set_ylim(0, 100)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title("segmenter on real prints: pretraining on simulation against a random start")
    return save_figure(fig, png)


@experiment("real-finetune")
def real_finetune(
    pretrained: O.opt(Path, "Segmenter trained on simulation (.pt).", "--pretrained"),
    train: O.opt(
        Path, "Box folder of real prints to fine-tune on (handskin ingest-boxes).", "--train"
    ),
    test: O.opt(Path, "Box folder of real prints to score on (another fold).", "--test"),
    out: O.OutOpt,
    ks: O.opt(str | None, "Real prints per run, comma-separated (default 10,30,100,342).") = None,
    draws: O.opt(str | None, "Draws per k, comma-separated (default 3,2,1,1).") = None,
    steps: O.opt(int | None, "Optimisation steps per run (count; default 300).") = None,
    replay: O.opt(
        int | None,
        "Simulated prints the pretrained start replays beside the real (count; "
        "default 300; 0: none).",
    ) = None,
    replay_from: O.opt(
        Path | None, "Simulated dataset to replay (default: the one --pretrained trained on)."
    ) = None,
    shift_mm: O.opt(
        float | None, "Copies of the real prints moved up to this far on the map (mm; default 18)."
    ) = None,
    turn_deg: O.opt(
        float | None,
        "Copies of the real prints turned up to this much (deg; default 15; with --shift-mm 0: "
        "plain repeats).",
    ) = None,
    quick: O.QuickOpt = False,
    seed: O.SeedOpt = 0,
    threads: O.ThreadsOpt = 2,
    progress: O.ProgressOpt = True,
) -> Path:
    """Fine-tune a segmenter on k real prints: pretrained on simulation against a random start.

    Part localisation on the other fold against k, as a chart and a table; the pretrained
    network with no real print as the zero-shot point. --quick: k 4 and 12, 6 steps.
    """
    base = QUICK if quick else FinetunePlan()
    changes = {
        "ks": O.parse_list("--ks", ks, int),
        "draws": O.parse_list("--draws", draws, int),
        "steps": steps,
        "replay": replay,
        "shift_mm": shift_mm,
        "turn_deg": turn_deg,
    }
    changes = {k: v for k, v in changes.items() if v is not None}
    plan = dataclasses.replace(base, seed=seed, threads=threads, **changes)
    O.check_out(out)
    run_finetune(pretrained, train, test, out, plan, progress, replay_from)
    return out / "report.md"
