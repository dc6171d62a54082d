"""Labels of `handskin evaluate` report rows (`learn.row_labels`): what tells two rows of
one method apart, in which order, and where a row with test-time flips goes."""

from __future__ import annotations


def test_report_labels_widths_and_puts_test_time_flips_after_their_row():
    """Rows of one method at two widths are told apart by width; a row with test-time flips
    follows the same model's plain row in the table."""
    from learn.eval_report import _init_text, _names
    from learn.evaluate import PAPER_TABLE8
    from learn.row_labels import row_labels

    a = {
        "arch": "segnet",
        "config": {"model": {"width": 0.25}},
        "checkpoint": "/r/a/best.pt",
        "train_data": {"path": "/d/hands9k", "n_train": 5384},
        "tta_views": None,
    }
    b = dict(a, config={"model": {"width": 0.5}}, checkpoint="/r/b/best.pt")
    rows = [a, b, dict(a, tta_views=[0, 1, 2]), dict(b, tta_views=[0, 1, 2])]
    labels = row_labels(rows)
    assert labels == [
        "SegNet, w0.25",
        "SegNet, w0.5",
        "SegNet + test-time flips, w0.25",
        "SegNet + test-time flips, w0.5",
    ]
    assert _names(PAPER_TABLE8, dict.fromkeys(labels)) == [
        "SegNet",
        "FCN",
        "SegNet, w0.25",
        "SegNet + test-time flips, w0.25",
        "SegNet, w0.5",
        "SegNet + test-time flips, w0.5",
    ]
    # the same width says nothing, so it is left out; the data, then the run folder, follow
    same = row_labels([a, dict(a, checkpoint="/r/c/best.pt")])
    assert same == ["SegNet, hands9k (5,384 train), a", "SegNet, hands9k (5,384 train), c"]
    # input size comes first: a row without one recorded has the model's default (68, 100)
    big = dict(a, config={"model": {"width": 0.25, "input_size": [136, 200]}})
    assert row_labels([a, big, dict(big, tta_views=[0, 1, 2])]) == [
        "SegNet, 68 x 100 px",
        "SegNet, 136 x 200 px",
        "SegNet + test-time flips",
    ]
    # a size both rows share says nothing, like a shared width
    assert row_labels([dict(b, input_size=[136, 200]), big]) == ["SegNet, w0.5", "SegNet, w0.25"]
    # the same network and size trained for two schedules: the epochs tell them apart
    long = dict(
        big,
        config={"model": big["config"]["model"], "train": {"epochs": 30}},
        checkpoint="/r/long/best.pt",
    )
    short = dict(long, config={**long["config"], "train": {"epochs": 15}})
    assert row_labels([short, long, dict(long, tta_views=[0, 1, 2])]) == [
        "SegNet, 15 epochs",
        "SegNet, 30 epochs",
        "SegNet + test-time flips",
    ]
    # ... or for one schedule in two number formats (no precision recorded: fp32)
    bf16 = dict(long, config={**long["config"], "precision": "bf16"}, checkpoint="/r/bf/best.pt")
    assert row_labels([long, bf16]) == ["SegNet, fp32 training", "SegNet, bf16 training"]
    # seed replicates: the seed, not the training data (whose split the seed also draws)
    s0, s1 = (
        dict(
            long,
            seed=k,
            checkpoint=f"/r/s{k}/best.pt",
            train_data={"path": "/d/hands9k", "n_train": 5384 - k},
        )
        for k in (0, 1)
    )
    assert row_labels([s0, s1, dict(bf16, seed=1)]) == [
        "SegNet, fp32 training, seed 0",
        "SegNet, fp32 training, seed 1",
        "SegNet, bf16 training",
    ]
    # ... or trained on a fourth view (the 180-degree turn), seeds included
    turn = dict(s1, config={**long["config"], "rot180": True}, checkpoint="/r/t/best.pt")
    assert row_labels([s0, s1, turn]) == [
        "SegNet, flips, seed 0",
        "SegNet, flips, seed 1",
        "SegNet, flips + 180°",
    ]
    shifted = dict(s0, config={**long["config"], "shift_px": 8}, checkpoint="/r/sh/best.pt")
    assert row_labels([s0, shifted]) == ["SegNet, flips", "SegNet, flips + shifts ±8 px"]
    # ... or with weight averaging (no ema_decay recorded: none), seed by seed
    ema = [
        dict(
            s,
            config={**s["config"], "train": {"epochs": 30, "ema_decay": 0.998}},
            checkpoint=f"/r/e{s['seed']}/best.pt",
        )
        for s in (s0, s1)
    ]
    assert row_labels([s0, s1, *ema]) == [
        "SegNet, no EMA, seed 0",
        "SegNet, no EMA, seed 1",
        "SegNet, EMA 0.998, seed 0",
        "SegNet, EMA 0.998, seed 1",
    ]
    # ... or with mixup, or label smoothing (neither recorded: none)
    hn = [dict(s, arch="handsnet") for s in (s0, s1)]
    mixed = dict(hn[0], config={**long["config"], "mixup_alpha": 0.2}, checkpoint="/r/m/best.pt")
    smooth = dict(
        hn[0],
        config={**long["config"], "train": {"epochs": 30, "label_smoothing": 0.1}},
        checkpoint="/r/ls/best.pt",
    )
    assert row_labels([*hn, mixed, smooth]) == [
        "HandsNet, flips, no label smoothing, seed 0",
        "HandsNet, flips, no label smoothing, seed 1",
        "HandsNet, flips + mixup α 0.2",
        "HandsNet, flips, label smoothing 0.1",
    ]
    # ... or with another optimizer or weight decay
    adamw = dict(
        hn[0],
        config={
            **long["config"],
            "train": {"epochs": 30, "optimizer": "adamw", "weight_decay": 0.05},
        },
        checkpoint="/r/aw/best.pt",
    )
    adam = dict(
        hn[0],
        config={
            **long["config"],
            "train": {"epochs": 30, "optimizer": "adam", "weight_decay": 1e-4},
        },
    )
    assert row_labels([adam, adamw]) == ["HandsNet, Adam wd 0.0001", "HandsNet, AdamW wd 0.05"]
    # ... or with a contactor-type head (none recorded: none), seed by seed
    typed = [
        dict(
            h,
            config={**long["config"], "aux_types_weight": 1.0},
            checkpoint=f"/r/t{h['seed']}/best.pt",
        )
        for h in hn
    ]
    assert row_labels([*hn, *typed]) == [
        "HandsNet, no type head, seed 0",
        "HandsNet, no type head, seed 1",
        "HandsNet, type head 1, seed 0",
        "HandsNet, type head 1, seed 1",
    ]
    # ... or distilled from a teacher (none recorded: none), seed by seed
    taught = dict(
        hn[0],
        config={
            **long["config"],
            "distill_from": "/r/vgg_x10/best.pt",
            "distill_weight": 0.5,
            "distill_temperature": 4.0,
        },
        checkpoint="/r/kd/best.pt",
    )
    assert row_labels([*hn, taught]) == [
        "HandsNet, no teacher, seed 0",
        "HandsNet, no teacher, seed 1",
        "HandsNet, distilled from vgg_x10 (a 0.5, T 4)",
    ]
    # ... or with HandsNet's dropout scaled (none recorded: the paper's)
    model = {**long["config"].get("model", {}), "dropout_scale": 0.0}
    nodrop = dict(hn[0], config={**long["config"], "model": model}, checkpoint="/r/nd/best.pt")
    assert row_labels([*hn, nodrop]) == [
        "HandsNet, paper's dropout, seed 0",
        "HandsNet, paper's dropout, seed 1",
        "HandsNet, dropout x 0",
    ]
    # fine-tuned from another run's checkpoint: its run folder, before the epochs (none
    # recorded: said only where it differs)
    scratch = [
        dict(long, init="random", train_data={"path": f"/d/{d}", "n_train": 9})
        for d in ("paper_k", "x2_k")
    ]
    tuned = dict(short, init="/r/seg_x2_k/best.pt", checkpoint="/r/ft/best.pt")
    assert row_labels([*scratch, tuned]) == [
        "SegNet, from scratch, paper_k (9 train)",
        "SegNet, from scratch, x2_k (9 train)",
        "SegNet, from seg_x2_k",
    ]
    assert row_labels([dict(long, init=None), tuned]) == [
        "SegNet, init unknown",
        "SegNet, from seg_x2_k",
    ]
    assert "bfloat16" in _init_text(dict(bf16, init="random"))
    assert "bfloat16" not in _init_text(dict(long, init="random"))
    assert "Distilled from `/r/vgg_x10/best.pt` (share 0.5 of the loss, temperature 4)." in (
        _init_text(dict(taught, init="random"))
    )
    assert "Distilled" not in _init_text(dict(long, init="random"))
    # ensembles: a repeated method is counted, and seed replicates name their seeds
    ens = {
        "arch": "ensemble",
        "checkpoint": "/r/a.pt + /r/b.pt + /r/c.pt",
        "members": [{"arch": "handsnet", "seed": k} for k in (0, 1, 2)],
    }
    mixed = dict(ens, members=[{"arch": "segnet", "seed": 0}, {"arch": "fcn16s", "seed": 0}])
    same_seed = dict(ens, members=[{"arch": "segnet", "seed": 0}] * 2)
    assert row_labels([ens, mixed, same_seed]) == [
        "mean of 3 x HandsNet (seeds 0, 1, 2)",
        "mean of SegNet + FCN",
        "mean of 2 x SegNet",
    ]
    # an ensemble's training data are its members': one folder with the seeds' counts, or each
    from learn.row_labels import data_name

    seeds = dict(
        ens,
        members=[
            {"arch": "handsnet", "seed": k, "train_data": {"path": "/d/forearm", "n_train": n}}
            for k, n in ((0, 2113), (1, 2098), (2, 2113))
        ],
    )
    assert data_name(seeds) == "forearm (2,098-2,113 train)"
    two = dict(
        ens,
        members=[
            {"train_data": {"path": "/d/hands9k", "n_train": 5384}},
            {"train_data": {"path": "/d/forearm", "n_train": 2113}},
        ],
    )
    assert data_name(two) == "hands9k (5,384 train) + forearm (2,113 train)"
    assert data_name(dict(ens, members=[two["members"][0]] * 2)) == "hands9k (5,384 train)"


def test_rows_of_one_run_folder_keep_their_own_table_rows():
    """Two files of one run folder (best.pt and last.pt; a HandsNet calibrated afresh and its
    int8 file) are told apart by file name, and the same file twice is numbered, so Table 3
    keeps every row instead of merging rows that share a label."""
    from learn.eval_report import _table3
    from learn.row_labels import row_labels

    a = {
        "arch": "handsnet",
        "task": "classify",
        "config": {"model": {}},
        "checkpoint": "/r/hn/best.pt",
        "train_data": {"path": "/d/paper", "n_train": 2479},
        "tta_views": None,
        "metrics": {"accuracy": 0.9182},
        "ms_per_image": {"fast": 3.49},
    }
    last = dict(a, checkpoint="/r/hn/last.pt", metrics={"accuracy": 0.9144})
    fresh = dict(a, int8={"backend": "onednn"}, metrics={"accuracy": 0.9201})
    saved = dict(
        a,
        checkpoint="/r/hn/best_int8.pt",
        int8={"backend": "onednn", "saved": True},
        metrics={"accuracy": 0.9211},
    )
    rows = [a, last, fresh, saved]
    labels = row_labels(rows)
    assert len(set(labels)) == len(rows)
    assert labels[1].endswith("last.pt") and labels[3].endswith("best_int8.pt")
    table = "\n".join(_table3(rows))
    for acc in ("91.82", "91.44", "92.01", "92.11"):
        assert f"| {acc} |" in table, table
    twice = row_labels([a, dict(a)])
    assert len(set(twice)) == 2 and twice[1].endswith("#2")
