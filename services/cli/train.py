"""`harvest train detector`: reproduce the detector's committed weights (see its MODEL_CARD)."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

DEFAULT_TRAIN = ("synth:1200:1", "scripted@0.1")
DEFAULT_VAL = ("synth:100:2",)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train models (the detector)", description=__doc__)
    tsub = p.add_subparsers(dest="what", metavar="WHAT")
    tsub.required = True
    d = tsub.add_parser(
        "detector",
        help="train OrangeNet from scratch or fine-tune it (seeded, resumable, GPU when present)",
        description="Train the orange detector on synthetic renders and the real photos; select "
        "on the validation sets; write the weights. Defaults reproduce the committed weights.",
    )
    d.add_argument(
        "--data",
        action="append",
        metavar="SET[@WEIGHT]",
        help="a training set and its share of the draws (repeatable). SET: a file in the shared "
        "JSON format; synth:N:SEED (the sim's renders, `harvest dataset synth`, rendered once "
        "into --synth-cache); scripted (scripted 2D scenes, drawn fresh). Default: "
        f"oranges_real/train.json, {', '.join(DEFAULT_TRAIN)}",
    )
    d.add_argument(
        "--val",
        action="append",
        metavar="SET",
        help="a validation set for model selection (repeatable; the mean AP50 is maximised). "
        f"Default: oranges_real/val.json, {', '.join(DEFAULT_VAL)}",
    )
    d.add_argument("--out-dir", type=Path, default=Path("runs/detector"), help="checkpoints")
    d.add_argument(
        "--synth-cache",
        type=Path,
        default=Path("runs/synth"),
        help="where synth:N:SEED data sets are rendered once and reused",
    )
    d.add_argument("--weights", type=Path, help="where to write the selected weights")
    d.add_argument("--epochs", type=int, default=150)
    d.add_argument("--iters-per-epoch", type=int, default=40)
    d.add_argument("--batch", type=int, default=16)
    d.add_argument("--lr", type=float, default=2e-3)
    d.add_argument("--seed", type=int, default=0)
    d.add_argument(
        "--eval-every", type=int, default=4, help="validate every N epochs (and after the last)"
    )
    d.add_argument(
        "--precision",
        choices=("auto", "bf16", "fp32"),
        default="auto",
        help="autocast of the forward pass: bf16 is ~2x faster on CPUs with AVX512-BF16 and on "
        "GPUs, several times slower where the CPU lacks it; auto (default): bf16 where native",
    )
    d.add_argument(
        "--ema-decay",
        type=float,
        default=0.998,
        help="decay of the weight average that is validated and shipped (0: off)",
    )
    d.add_argument("--threads", type=int, default=2, help="torch CPU threads (ignored on GPU)")
    d.add_argument(
        "--workers",
        type=int,
        default=0,
        help="processes building the batches (0: in the training process, the committed "
        "recipe's draws; N > 0: each batch seeded by (seed, epoch, batch), the same for any N; "
        "a GPU needs many)",
    )
    d.add_argument(
        "--init",
        type=Path,
        metavar="WEIGHTS",
        help="fine-tune: start from these weights (e.g. the committed ones, on your own "
        "photos) instead of a random initialisation; their architecture is kept",
    )
    d.add_argument("--resume", action="store_true", help="continue from OUT_DIR/last.pt")
    d.set_defaults(func=cmd_train_detector)


def cmd_train_detector(args: argparse.Namespace) -> int:
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    from services.detector.data import DatasetError
    from services.detector.infer import WeightsError
    from services.detector.paths import DEFAULT_WEIGHTS, real_data_dir
    from services.detector.train import TrainConfig, finalize, parse_spec, pick_device, train

    real = real_data_dir()
    cfg = TrainConfig(
        train=[parse_spec(a) for a in (args.data or [str(real / "train.json"), *DEFAULT_TRAIN])],
        val=[parse_spec(a) for a in (args.val or [str(real / "val.json"), *DEFAULT_VAL])],
        out_dir=str(args.out_dir),
        weights_out=str(args.weights or DEFAULT_WEIGHTS),
        epochs=args.epochs,
        iters_per_epoch=args.iters_per_epoch,
        batch=args.batch,
        lr=args.lr,
        seed=args.seed,
        eval_every=args.eval_every,
        precision=args.precision,
        ema_decay=args.ema_decay,
        threads=args.threads,
        workers=args.workers,
        synth_cache=str(args.synth_cache),
        init_weights=str(args.init) if args.init else None,
    )
    print(f"training on {pick_device()}; checkpoints in {cfg.out_dir}", file=sys.stderr)
    try:
        with Progress(
            TextColumn("[bold]train detector"),
            BarColumn(),
            TextColumn("{task.completed}/{task.total} it  loss {task.fields[loss]:.3f}"),
            TimeRemainingColumn(),
        ) as bar:
            task = bar.add_task("train", total=cfg.epochs * cfg.iters_per_epoch, loss=0.0)
            summary = train(
                cfg,
                resume=args.resume,
                on_iter=lambda i, n, loss: bar.update(task, completed=i, loss=loss),
                log=bar.console.print,
            )
        command = "harvest " + shlex.join(sys.argv[1:])
        meta = finalize(cfg, summary, command)
    except (DatasetError, WeightsError) as exc:
        print(f"harvest train detector: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(meta, indent=2))
    return 0
