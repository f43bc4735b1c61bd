"""`harvest train detector`: train OrangeNet from scratch, seeded, resumable, GPU when present.

Each epoch draws a fixed number of batches from the training sets (weighted), builds each
sample by augmentation (random placement or a 2x2 mosaic, then colour and noise), and steps
AdamW on a cosine schedule. After every ``eval_every`` epochs the model is scored on each
validation set (AP50 by pycocotools); the best mean AP50 is kept. ``last.pt`` in the run
folder holds everything needed to resume (model, optimiser, epoch, RNG-free schedule).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from services.detector.augment import mosaic, photometric, random_placement
from services.detector.data import DatasetError, Sample, load_dataset
from services.detector.ema import WeightAverage
from services.detector.evaluate import evaluate
from services.detector.infer import OrangeDetector, load_weights, save_weights
from services.detector.net import NetConfig, OrangeNet
from services.detector.targets import focal_loss, giou_loss, make_targets

SCRIPTED = "scripted"
"""Data-set name of the scripted 2D scenes (services/testkit/scene2d.py): drawn fresh for
every training sample, and written once (seeded) as a validation set in the run folder."""
SCRIPTED_VAL_FRAMES = 60
SCRIPTED_VAL_SEED = 10_000


SYNTH_PREFIX = "synth:"
"""``synth:FRAMES:SEED``: the sim's domain-randomised renders (`harvest dataset synth --frames
FRAMES --seed SEED`), rendered once into the synth cache folder and reused."""


@dataclass
class DataSpec:
    """One data set file (or ``scripted``, or ``synth:FRAMES:SEED``), its images root, and
    its share of the training draws."""

    json_path: str
    images_root: str | None = None
    weight: float = 1.0


def parse_spec(arg: str) -> DataSpec:
    """``NAME[@WEIGHT]`` → DataSpec (NAME: a JSON file, ``scripted`` or ``synth:N:SEED``)."""
    name, _, weight = arg.partition("@")
    return DataSpec(name, None, float(weight) if weight else 1.0)


def synth_dataset(frames: int, seed: int, cache_dir: Path, log: Callable[[str], None]) -> Path:
    """labels.json of the sim's synthetic renders (frames, seed), rendered if not cached."""
    out = cache_dir / f"synth-n{frames}-s{seed}"
    labels = out / "labels.json"
    if labels.exists() and len(json.loads(labels.read_text())) == frames:
        return labels
    from services.sim.dataset import synth

    log(f"rendering {frames} synthetic frames (seed {seed}) into {out} ...")
    synth(out, frames, seed)
    return labels


def resolve(
    specs: list[DataSpec],
    out_dir: Path | None,
    cache_dir: Path,
    log: Callable[[str], None] = print,
) -> list[DataSpec]:
    """Specs with ``synth:N:SEED`` replaced by the rendered data set, and (validation only)
    ``scripted`` by a seeded scripted data set written once into the run folder."""
    from services.testkit.scene2d import write_dataset

    out = []
    for s in specs:
        if s.json_path.startswith(SYNTH_PREFIX):
            try:
                _, n, seed = s.json_path.split(":")
                path = synth_dataset(int(n), int(seed), cache_dir, log)
            except ValueError:
                raise DatasetError(f"{s.json_path!r}: expected synth:FRAMES:SEED") from None
            s = DataSpec(str(path), None, s.weight)
        elif s.json_path == SCRIPTED and out_dir is not None:
            path = out_dir / "scripted-val" / "scripted_val.json"
            if not path.exists():
                write_dataset(path.parent, SCRIPTED_VAL_FRAMES, SCRIPTED_VAL_SEED, path.name)
            s = DataSpec(str(path), None, s.weight)
        out.append(s)
    return out


@dataclass
class TrainConfig:
    train: list[DataSpec]
    val: list[DataSpec]
    out_dir: str
    weights_out: str
    epochs: int = 150
    iters_per_epoch: int = 40
    batch: int = 16
    lr: float = 2e-3
    weight_decay: float = 5e-4
    warmup_iters: int = 100
    mosaic_p: float = 0.5
    giou_weight: float = 5.0
    eval_every: int = 4
    seed: int = 0
    threads: int = 2
    # bf16 autocast: ~2x faster on CPUs with AVX512-BF16 (and on GPUs); several times slower
    # where the CPU lacks it (emulated). auto: bf16 where it is native, else fp32.
    precision: str = "auto"
    ema_decay: float = 0.998  # 0 turns the weight average off (the last iterate is validated)
    synth_cache: str = "runs/synth"
    # Processes building the batches (sampling + augmentation). 0: in the training process, one
    # generator per epoch (the committed recipe). N > 0: a DataLoader of N workers, each batch
    # from its own generator (seed, epoch, batch): the same batches for any N (a GPU needs many).
    workers: int = 0
    # Fine-tuning: start from these weights (their architecture config replaces ``net``)
    # instead of a random initialisation. None: from scratch (the committed recipe).
    init_weights: str | None = None
    net: dict[str, Any] = field(default_factory=lambda: NetConfig().to_dict())


def pick_device() -> torch.device:
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


PRECISIONS = ("auto", "bf16", "fp32")


def cpu_has_native_bf16(cpuinfo: Path = Path("/proc/cpuinfo")) -> bool:
    """Whether the CPU computes bf16 natively (AVX512-BF16 or AMX); False where unknown."""
    try:
        flags = cpuinfo.read_text().split()
    except OSError:
        return False
    return "avx512_bf16" in flags or "amx_bf16" in flags


def resolve_precision(precision: str, device: torch.device) -> str:
    """``auto`` → bf16 where the device computes it natively, else fp32; others as given."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision {precision!r}: expected one of {PRECISIONS}")
    if precision != "auto":
        return precision
    if device.type == "cuda":
        return "bf16" if torch.cuda.is_bf16_supported() else "fp32"
    return "bf16" if cpu_has_native_bf16() else "fp32"


def autocast(cfg: TrainConfig, device: torch.device) -> torch.autocast:
    """The forward pass's autocast context for the configured precision."""
    bf16 = resolve_precision(cfg.precision, device) == "bf16"
    return torch.autocast(device.type, dtype=torch.bfloat16, enabled=bf16)


class _Pool:
    """Training samples of several data sets, drawn with per-set weights."""

    def __init__(self, specs: list[DataSpec]) -> None:
        self.sets: list[list[Sample]] = []
        w = []
        for s in specs:
            if s.json_path == SCRIPTED:
                self.sets.append([])  # drawn fresh each time, see draw()
                w.append(s.weight)
                continue
            samples = load_dataset(
                Path(s.json_path), Path(s.images_root) if s.images_root else None
            )
            self.sets.append(samples)
            w.append(s.weight)
        self.p = np.asarray(w, float) / sum(w)
        self._cache: dict[Path, np.ndarray] = {}

    def draw(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        k = int(rng.choice(len(self.sets), p=self.p))
        if not self.sets[k]:
            from services.testkit.scene2d import random_scene

            f = random_scene(rng).frame(int(rng.integers(0, 80)))
            boxes = [v.box_xyxy_px for v in f.fruits if v.box_xyxy_px and v.visible_fraction >= 0.5]
            return f.frame.rgb, np.asarray(boxes, np.float32).reshape(-1, 4)
        s = self.sets[k][int(rng.integers(len(self.sets[k])))]
        img = self._cache.get(s.path)
        if img is None:
            img = s.load_rgb()
            if img.size <= 700_000 and len(self._cache) < 4000:  # small photos stay in memory
                self._cache[s.path] = img
        return img, s.boxes_xyxy_px


def make_batch(
    pool: _Pool, cfg: TrainConfig, ncfg: NetConfig, rng: np.random.Generator
) -> tuple[torch.Tensor, ...]:
    W, H, st = ncfg.input_w_px, ncfg.input_h_px, ncfg.stride
    imgs, heats, boxes_t, weights = [], [], [], []
    for _ in range(cfg.batch):
        if rng.random() < cfg.mosaic_p:
            img, boxes = mosaic([pool.draw(rng) for _ in range(4)], W, H, rng)
        else:
            img, boxes = random_placement(*pool.draw(rng), W, H, rng)
        img = photometric(img, rng)
        h, b, w = make_targets(boxes, H // st, W // st, st)
        imgs.append(img)
        heats.append(h)
        boxes_t.append(b)
        weights.append(w)
    x = torch.from_numpy(np.stack(imgs)).permute(0, 3, 1, 2).float().div_(255.0)
    return (
        x,
        torch.from_numpy(np.stack(heats)),
        torch.from_numpy(np.stack(boxes_t)),
        torch.from_numpy(np.stack(weights)),
    )


class _BatchSet(Dataset[tuple[torch.Tensor, ...]]):
    """Batch number ``it`` of the run (all epochs), built from the generator of (seed, epoch,
    index in the epoch): what a batch holds depends on neither the worker nor the resume point."""

    def __init__(self, pool: _Pool, cfg: TrainConfig, ncfg: NetConfig) -> None:
        self.pool, self.cfg, self.ncfg = pool, cfg, ncfg

    def __len__(self) -> int:
        return self.cfg.epochs * self.cfg.iters_per_epoch

    def __getitem__(self, it: int) -> tuple[torch.Tensor, ...]:
        epoch, i = divmod(it, self.cfg.iters_per_epoch)
        rng = np.random.default_rng([self.cfg.seed, epoch, i])
        return make_batch(self.pool, self.cfg, self.ncfg, rng)


def _worker_init(_: int) -> None:
    cv2.setNumThreads(1)  # the workers are the parallelism; OpenCV's own threads oversubscribe


def batches(
    pool: _Pool, cfg: TrainConfig, ncfg: NetConfig, start_epoch: int, pin_memory: bool = False
) -> Iterator[tuple[torch.Tensor, ...]]:
    """The training batches from ``start_epoch`` to the end, in order (see TrainConfig.workers)."""
    if cfg.workers < 0:
        raise ValueError(f"workers {cfg.workers}: must be >= 0")
    if cfg.workers == 0:
        for epoch in range(start_epoch, cfg.epochs):
            # One generator per epoch: a resumed run draws what the uninterrupted one would.
            rng = np.random.default_rng([cfg.seed, epoch])
            for _ in range(cfg.iters_per_epoch):
                yield make_batch(pool, cfg, ncfg, rng)
        return
    data = _BatchSet(pool, cfg, ncfg)
    yield from DataLoader(
        data,
        batch_size=None,  # an item is a whole batch
        sampler=range(start_epoch * cfg.iters_per_epoch, len(data)),
        num_workers=cfg.workers,
        worker_init_fn=_worker_init,
        pin_memory=pin_memory,
        prefetch_factor=4,
        # Fresh interpreters: forking after OpenCV/torch thread pools ran is unsafe (forked
        # workers hung now and then in the unit test); costs a few seconds once per run.
        multiprocessing_context="spawn",
    )


def lr_at(cfg: TrainConfig, it: int) -> float:
    total = cfg.epochs * cfg.iters_per_epoch
    if it < cfg.warmup_iters:
        return cfg.lr * (it + 1) / cfg.warmup_iters
    t = (it - cfg.warmup_iters) / max(1, total - cfg.warmup_iters)
    return cfg.lr * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(t, 1.0))))


def validate(net: OrangeNet, specs: list[DataSpec], device: torch.device) -> dict[str, float]:
    """AP50 and AP50:95 per validation set (low score threshold, as AP needs)."""
    was_training = net.training
    det = OrangeDetector(net, score_min=0.01, device=device)
    out: dict[str, float] = {}
    for s in specs:
        samples = load_dataset(Path(s.json_path), Path(s.images_root) if s.images_root else None)
        m = evaluate(samples, det.detect, 0.3)
        name = Path(s.json_path).stem
        out[f"{name}/ap50"] = m.ap50
        out[f"{name}/ap50_95"] = m.ap50_95
    net.train(was_training)
    return out


def train(
    cfg: TrainConfig,
    resume: bool = False,
    on_iter: Callable[[int, int, float], None] | None = None,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Train; returns the summary (best epoch and its validation metrics)."""
    device = pick_device()
    if device.type == "cpu":
        torch.set_num_threads(cfg.threads)
    cfg.precision = resolve_precision(cfg.precision, device)  # config.json records the one used
    log(f"precision {cfg.precision} on {device.type}")
    torch.manual_seed(cfg.seed)
    start = load_weights(Path(cfg.init_weights)) if cfg.init_weights else None
    if start is not None:
        cfg.net = start.net.cfg.to_dict()
        log(f"fine-tuning from {cfg.init_weights} ({start.version})")
    ncfg = NetConfig.from_dict(cfg.net)
    net = (start.net if start is not None else OrangeNet(ncfg)).to(device)
    opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    ema = WeightAverage(net, cfg.ema_decay) if cfg.ema_decay > 0 else None
    # What is validated, selected and saved (the average is a copy of the net: an OrangeNet).
    shipped = cast(OrangeNet, ema.model) if ema else net
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg.train = resolve(cfg.train, None, Path(cfg.synth_cache), log)
    cfg.val = resolve(cfg.val, out, Path(cfg.synth_cache), log)
    (out / "config.json").write_text(json.dumps(asdict(cfg), indent=2))
    start_epoch = 0
    best: dict[str, Any] = {"score": -1.0, "epoch": -1, "metrics": {}}
    history: list[dict[str, Any]] = []
    if resume and (out / "last.pt").exists():
        ck = torch.load(out / "last.pt", map_location=device, weights_only=False)
        net.load_state_dict(ck["model"])
        opt.load_state_dict(ck["opt"])
        if ema:
            ema.load_state_dict(ck["ema"])
        start_epoch, best, history = ck["epoch"] + 1, ck["best"], ck["history"]
        log(f"resumed from {out / 'last.pt'} at epoch {start_epoch}")
    stream = batches(_Pool(cfg.train), cfg, ncfg, start_epoch, pin_memory=device.type == "cuda")
    net.train()
    for epoch in range(start_epoch, cfg.epochs):
        torch.manual_seed(cfg.seed * 100_003 + epoch)
        t0, losses = time.perf_counter(), []
        for i in range(cfg.iters_per_epoch):
            it = epoch * cfg.iters_per_epoch + i
            for g in opt.param_groups:
                g["lr"] = lr_at(cfg, it)
            x, heat, box_t, weight = (t.to(device, non_blocking=True) for t in next(stream))
            with autocast(cfg, device):
                hm, ltrb = net(x)
            # The losses in fp32: focal terms of tiny probabilities lose everything in bf16.
            hm, ltrb = hm.float(), ltrb.float()
            loss = focal_loss(hm, heat) + cfg.giou_weight * giou_loss(
                ltrb, box_t, weight, ncfg.stride
            )
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), 10.0)
            opt.step()
            if ema:
                ema.update(net)
            losses.append(loss.item())
            if on_iter:
                on_iter(it + 1, cfg.epochs * cfg.iters_per_epoch, float(np.mean(losses[-20:])))
        row: dict[str, Any] = {
            "epoch": epoch,
            "loss": float(np.mean(losses)),
            "s": time.perf_counter() - t0,
        }
        if (epoch + 1) % cfg.eval_every == 0 or epoch + 1 == cfg.epochs:
            metrics = validate(shipped, cfg.val, device)
            row.update(metrics)
            aps = [v for k, v in metrics.items() if k.endswith("/ap50")]
            score = float(np.mean(aps)) if aps else -float(row["loss"])
            if score > best["score"]:
                best = {"score": score, "epoch": epoch, "metrics": metrics}
                save_weights(out / "best.pt", shipped, {"epoch": epoch, "val": metrics})
        history.append(row)
        log(json.dumps(row))
        # Written whole, then renamed: a run killed while saving keeps the previous last.pt.
        torch.save(
            {
                "model": net.state_dict(),
                "opt": opt.state_dict(),
                "ema": ema.state_dict() if ema else None,
                "epoch": epoch,
                "best": best,
                "history": history,
            },
            out / "last.pt.part",
        )
        (out / "last.pt.part").replace(out / "last.pt")
    return {"best": best, "history": history}


def choose_threshold(net: OrangeNet, specs: list[DataSpec], device: torch.device) -> float:
    """The operating threshold: the score that maximises the mean F1 (IoU 0.5) over the
    validation sets, on a 0.05 grid."""
    from services.detector.evaluate import greedy_matches

    det = OrangeDetector(net, score_min=0.05, device=device)
    grid = np.round(np.arange(0.1, 0.91, 0.05), 2)
    f1s = []
    for s in specs:
        samples = load_dataset(Path(s.json_path), Path(s.images_root) if s.images_root else None)
        preds = [(x.boxes_xyxy_px, det.detect(x.load_rgb())) for x in samples]
        row = []
        for t in grid:
            tp = sum(greedy_matches(g, d[d[:, 4] >= t]) for g, d in preds)
            nd = sum(int((d[:, 4] >= t).sum()) for _, d in preds)
            ng = sum(len(g) for g, _ in preds)
            row.append(2 * tp / max(nd + ng, 1))
        f1s.append(row)
    return float(grid[int(np.argmax(np.mean(f1s, axis=0)))])


def finalize(cfg: TrainConfig, summary: dict[str, Any], command: str) -> dict[str, Any]:
    """Write the best checkpoint as the service's weights with its operating threshold."""
    import hashlib

    device = pick_device()
    cfg.val = resolve(cfg.val, Path(cfg.out_dir), Path(cfg.synth_cache))
    best = load_weights(Path(cfg.out_dir) / "best.pt")
    net = best.net.to(device)
    threshold = choose_threshold(net, cfg.val, device)
    # .cpu(): the net sits on the training device (a CUDA tensor has no .numpy()).
    digest = hashlib.sha256(
        b"".join(v.detach().cpu().numpy().tobytes() for v in net.state_dict().values())
    ).hexdigest()[:8]
    meta = {
        "version": f"v1-{digest}",
        "epoch": summary["best"]["epoch"],
        "val": summary["best"]["metrics"],
        "score_threshold": threshold,
        "command": command,
        "config": asdict(cfg),
        "device": device.type,
    }
    save_weights(Path(cfg.weights_out), net.cpu(), meta)
    return {k: v for k, v in meta.items() if k != "config"}
