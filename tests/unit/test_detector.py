"""Detector: network shapes and decoding, targets and losses, weights checks, data checks,
COCO AP, the HSV baseline, and a seeded, resumable training run."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from services.detector.data import DatasetError, load_dataset
from services.detector.evaluate import (
    box_size_ratios,
    coco_ap,
    coco_aps,
    greedy_matches,
    iou_matrix,
)
from services.detector.hsv import HsvDetector
from services.detector.infer import OrangeDetector, WeightsError, load_weights, save_weights
from services.detector.net import NetConfig, OrangeNet, decode
from services.detector.targets import focal_loss, giou_loss, make_targets
from services.detector.train import DataSpec, TrainConfig
from services.testkit.scene2d import Scene2D

SMALL = NetConfig(widths=(8, 8, 16, 16), blocks=(1, 1, 1), neck=8, input_w_px=64, input_h_px=48)


def test_network_output_shapes_and_decoding_of_a_single_peak() -> None:
    net = OrangeNet(SMALL).eval()
    hm, ltrb = net(torch.rand(2, 3, 48, 64))
    assert hm.shape == (2, 1, 12, 16) and ltrb.shape == (2, 4, 12, 16)
    assert (ltrb >= 0).all()
    logits = torch.full((1, 1, 12, 16), -10.0)
    logits[0, 0, 5, 7] = 5.0
    dist = torch.full((1, 4, 12, 16), 6.0)
    (boxes,) = decode(logits, dist, 4, 0.5, 10)
    np.testing.assert_allclose(boxes[0, :4].numpy(), [24, 16, 36, 28])  # centre (30, 22)


def test_targets_peak_at_box_centres_and_a_perfect_box_has_zero_giou_loss() -> None:
    boxes = np.array([[10, 10, 26, 26], [40, 20, 56, 44]], np.float32)
    heat, box_t, weight = make_targets(boxes, 12, 16, 4)
    assert heat.max() == 1.0 and int((heat == 1.0).sum()) == 2
    assert heat[0, 4, 4] == 1.0  # centre (18, 18) px is the centre of cell (4, 4) at stride 4
    ys, xs = np.nonzero(weight[0])
    cx, cy = (xs + 0.5) * 4, (ys + 0.5) * 4
    t = box_t[:, ys, xs]
    ltrb = np.zeros((1, 4, 12, 16), np.float32)
    ltrb[0, :, ys, xs] = np.stack([cx - t[0], cy - t[1], t[2] - cx, t[3] - cy], 1)
    loss = giou_loss(
        torch.from_numpy(ltrb), torch.from_numpy(box_t[None]), torch.from_numpy(weight[None]), 4
    )
    assert float(loss) < 1e-4
    logits = torch.logit(torch.from_numpy(heat[None]).clamp(1e-4, 1 - 1e-4))
    perfect = float(focal_loss(logits, torch.from_numpy(heat[None])))
    assert (
        perfect < 0.05 < float(focal_loss(torch.zeros_like(logits), torch.from_numpy(heat[None])))
    )


def test_weights_that_are_missing_or_do_not_match_are_refused_with_path_and_reason(
    tmp_path: Path,
) -> None:
    with pytest.raises(WeightsError, match=r"nothere\.pt: not found"):
        load_weights(tmp_path / "nothere.pt")
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a torch file")
    with pytest.raises(WeightsError, match="cannot be read"):
        load_weights(junk)
    other = tmp_path / "other.pt"
    torch.save({"arch": "yolo", "state_dict": {}}, other)
    with pytest.raises(WeightsError, match="architecture 'yolo'"):
        load_weights(other)
    good = tmp_path / "small.pt"
    save_weights(good, OrangeNet(SMALL), {"version": "t"})
    blob = torch.load(good, weights_only=True)
    blob["config"]["neck"] = 12  # the saved tensors no longer fit the architecture
    torch.save(blob, tmp_path / "bad.pt")
    with pytest.raises(WeightsError, match="does not match the architecture"):
        load_weights(tmp_path / "bad.pt")
    assert load_weights(good).version == "t"


def tiny_config(out: Path, train_set: Path, val_set: Path, **kw: object) -> TrainConfig:
    """A training run of the small network over a few scripted images, in ``out``."""
    base: dict = dict(
        train=[DataSpec(str(train_set))],
        val=[DataSpec(str(val_set))],
        out_dir=str(out),
        weights_out=str(out / "w.pt"),
        epochs=1,
        iters_per_epoch=2,
        batch=2,
        eval_every=1,
        warmup_iters=1,
        net=SMALL.to_dict(),
    )
    return TrainConfig(**(base | kw))


def write_dataset(root: Path, n: int, seed: int) -> Path:
    entries = []
    for k in range(n):
        f = Scene2D(seed=seed + k, n_fruit=5, sweep=None, width_px=160, height_px=120).frame(0)
        name = f"img{seed}_{k}.png"
        cv2.imwrite(str(root / name), cv2.cvtColor(f.frame.rgb, cv2.COLOR_RGB2BGR))
        boxes = [list(v.box_xyxy_px) for v in f.fruits if v.box_xyxy_px is not None]
        entries.append({"image": name, "width": 160, "height": 120, "boxes": boxes})
    path = root / f"set{seed}.json"
    path.write_text(json.dumps(entries))
    return path


def test_dataset_errors_name_the_file_and_the_entry(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="not found"):
        load_dataset(tmp_path / "none.json")
    p = tmp_path / "bad.json"
    p.write_text(
        json.dumps([{"image": "a.png", "width": 10, "height": 10, "boxes": [[5, 5, 1, 1]]}])
    )
    with pytest.raises(DatasetError, match="entry 0: an inverted box"):
        load_dataset(p)
    good = write_dataset(tmp_path, 1, 0)
    (s,) = load_dataset(good)
    s2 = type(s)(s.path, 99, 120, s.boxes_xyxy_px)
    with pytest.raises(DatasetError, match="is 160x120 px, the data set says 99x120"):
        s2.load_rgb()


def test_coco_ap_of_perfect_and_of_half_wrong_detections() -> None:
    gt = [np.array([[0, 0, 10, 10], [20, 20, 40, 40]], float)]
    perfect = [np.c_[gt[0], [0.9, 0.8]]]
    assert coco_ap(gt, perfect) == pytest.approx((1.0, 1.0))
    half = [np.array([[0, 0, 10, 10, 0.9], [60, 60, 70, 70, 0.95]], float)]
    ap50, _ = coco_ap(gt, half)
    assert 0.2 < ap50 < 0.6
    assert greedy_matches(gt[0], half[0]) == 1
    assert iou_matrix(gt[0], gt[0]).diagonal().tolist() == [1.0, 1.0]


def test_hsv_baseline_finds_the_scripted_fruit() -> None:
    f = Scene2D(seed=3, n_fruit=6, sweep=None).frame(0)
    d = HsvDetector().detect(f.frame.rgb)
    gt = np.array([v.box_xyxy_px for v in f.fruits])
    assert greedy_matches(gt, d) >= 5


def test_training_is_seeded_and_resumes_to_the_same_weights(tmp_path: Path) -> None:
    from services.detector.train import finalize, train

    train_set = write_dataset(tmp_path, 4, 10)
    val_set = write_dataset(tmp_path, 2, 20)

    def cfg(out: str, epochs: int) -> TrainConfig:
        return tiny_config(tmp_path / out, train_set, val_set, epochs=epochs)

    quiet = lambda _: None  # noqa: E731
    train(cfg("a", 2), log=quiet)
    train(cfg("b", 1), log=quiet)
    summary = train(cfg("b", 2), resume=True, log=quiet)
    a = torch.load(tmp_path / "a" / "last.pt", weights_only=False)["model"]
    b = torch.load(tmp_path / "b" / "last.pt", weights_only=False)["model"]
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert [h["epoch"] for h in summary["history"]] == [0, 1]
    assert "set20/ap50" in summary["best"]["metrics"]
    det = OrangeDetector(load_weights(tmp_path / "b" / "best.pt").net, score_min=0.0)
    assert det.detect(np.zeros((120, 160, 3), np.uint8)).shape[1] == 5
    meta = finalize(cfg("b", 2), summary, "harvest train detector --epochs 2")
    shipped = load_weights(tmp_path / "b" / "w.pt")
    assert meta["version"].startswith("v1-") and 0.0 <= meta["score_threshold"] <= 1.0
    assert all(torch.equal(shipped.net.state_dict()[k], v) for k, v in best_state(tmp_path).items())


def best_state(tmp_path: Path) -> dict[str, torch.Tensor]:
    return dict(load_weights(tmp_path / "b" / "best.pt").net.state_dict())


def test_weight_average_starts_at_the_net_and_follows_it_with_a_ramped_decay() -> None:
    from services.detector.ema import WeightAverage

    net = OrangeNet(SMALL)
    ema = WeightAverage(net, decay=0.9, ramp_updates=1.0)
    first = {k: v.clone() for k, v in net.state_dict().items()}
    with torch.no_grad():
        for p in net.parameters():
            p.add_(1.0)
    ema.update(net)  # decay 0.9 * (1 - e^-1) = 0.569: 43 % of the way to the moved weights
    d = ema.current_decay()
    assert 0.56 < d < 0.58
    name = next(k for k, _ in net.named_parameters())
    torch.testing.assert_close(ema.model.state_dict()[name], first[name] + (1 - d))
    assert not any(p.requires_grad for p in ema.model.parameters())
    with pytest.raises(ValueError, match=r"decay 1\.0"):
        WeightAverage(net, decay=1.0)


def test_inference_folds_batch_norms_without_changing_the_outputs_or_the_given_net() -> None:
    from services.detector.net import fused_for_inference

    torch.manual_seed(0)
    net = OrangeNet(SMALL)
    net.train()
    for _ in range(3):  # give the batch norms statistics of their own
        net(torch.rand(4, 3, 48, 64))
    net.eval()
    x = torch.rand(2, 3, 48, 64)
    fused = fused_for_inference(net)
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in fused.modules())
    assert any(isinstance(m, torch.nn.BatchNorm2d) for m in net.modules())
    with torch.inference_mode():
        for a, b in zip(
            net(x), fused(x.contiguous(memory_format=torch.channels_last)), strict=True
        ):
            torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-4)


def test_an_unknown_training_precision_is_refused_by_name() -> None:
    from services.detector.train import TrainConfig, autocast

    cfg = TrainConfig(train=[], val=[], out_dir="x", weights_out="x.pt", precision="fp8")
    with pytest.raises(ValueError, match="precision 'fp8'"):
        autocast(cfg, torch.device("cpu"))


def test_auto_precision_is_bf16_only_on_a_cpu_that_computes_it_natively(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from services.detector import train as tr

    info = tmp_path / "cpuinfo"
    info.write_text("flags\t\t: fpu sse2 avx2 avx512f avx512_bf16 amx_tile\n")
    assert tr.cpu_has_native_bf16(info)
    info.write_text("flags\t\t: fpu sse2 avx2 fma\n")  # bf16 would be emulated
    assert not tr.cpu_has_native_bf16(info)
    assert not tr.cpu_has_native_bf16(tmp_path / "absent")
    cpu = torch.device("cpu")
    monkeypatch.setattr(tr, "cpu_has_native_bf16", lambda: False)
    assert tr.resolve_precision("auto", cpu) == "fp32"
    assert tr.resolve_precision("bf16", cpu) == "bf16"  # asked for: kept
    monkeypatch.setattr(tr, "cpu_has_native_bf16", lambda: True)
    assert tr.resolve_precision("auto", cpu) == "bf16"
    assert tr.resolve_precision("fp32", cpu) == "fp32"


def test_parallel_batches_are_the_same_for_any_worker_count_and_resume_point(
    tmp_path: Path,
) -> None:
    from services.detector.train import DataSpec, TrainConfig, _BatchSet, _Pool, batches, train

    train_set = write_dataset(tmp_path, 3, 30)
    specs = [DataSpec(str(train_set)), DataSpec("scripted", weight=0.5)]
    cfg = TrainConfig(
        train=specs, val=[], out_dir="x", weights_out="x.pt", epochs=2, iters_per_epoch=3, batch=2
    )
    pool = _Pool(specs)

    def drawn(workers: int, start_epoch: int = 0) -> list[tuple[torch.Tensor, ...]]:
        cfg.workers = workers
        return list(batches(pool, cfg, SMALL, start_epoch))

    two = drawn(2)
    assert len(two) == 6 and two[0][0].shape == (2, 3, 48, 64)
    reference = [_BatchSet(pool, cfg, SMALL)[it] for it in range(6)]  # in this process
    for got in (two, drawn(1), drawn(2, start_epoch=1)):
        for a, b in zip(got, reference[6 - len(got) :], strict=True):
            assert all(torch.equal(u, v) for u, v in zip(a, b, strict=True))
    assert not torch.equal(two[0][0], two[1][0])  # each batch its own draws
    serial = drawn(0)  # the committed recipe's draws: one generator per epoch, unchanged
    assert not torch.equal(serial[1][0], two[1][0])
    with pytest.raises(ValueError, match="workers -1"):
        drawn(-1)

    val_set = write_dataset(tmp_path, 2, 40)
    cfg = tiny_config(tmp_path / "w2", train_set, val_set, epochs=2, eval_every=2, workers=2)
    summary = train(cfg, log=lambda _: None)
    assert [h["epoch"] for h in summary["history"]] == [0, 1]
    assert (tmp_path / "w2" / "last.pt").exists()
    assert not (tmp_path / "w2" / "last.pt.part").exists()


def test_fine_tuning_starts_from_the_given_weights_and_keeps_their_architecture(
    tmp_path: Path,
) -> None:
    from services.detector.train import train

    train_set = write_dataset(tmp_path, 4, 10)
    torch.manual_seed(7)
    start = OrangeNet(SMALL)
    save_weights(tmp_path / "start.pt", start, {"version": "v1-start"})
    cfg = tiny_config(tmp_path / "ft", train_set, train_set)
    cfg.lr = 0.0  # no step: the parameters must stay those of the start weights
    cfg.init_weights = str(tmp_path / "start.pt")
    cfg.net = NetConfig().to_dict()  # the start weights' (smaller) architecture must replace it
    train(cfg, log=lambda _: None)
    tuned = torch.load(tmp_path / "ft" / "last.pt", weights_only=False)["model"]
    for name, p in start.named_parameters():
        assert torch.equal(tuned[name], p.detach()), name
    assert NetConfig.from_dict(cfg.net) == SMALL

    cfg.init_weights = str(tmp_path / "missing.pt")
    with pytest.raises(WeightsError, match=r"missing\.pt: not found"):
        train(cfg, log=lambda _: None)


def test_ap30_and_box_ratios_tell_a_label_style_from_missed_fruit() -> None:
    # Labels 1/0.65 the size of the (concentric) detections: IoU 0.4225, under AP50's 0.5.
    gt = [np.array([[100.0, 100.0, 200.0, 200.0], [300.0, 100.0, 340.0, 140.0]])]
    small = []
    for x1, y1, x2, y2 in gt[0]:
        cx, cy, w, h = (x1 + x2) / 2, (y1 + y2) / 2, (x2 - x1) * 0.65, (y2 - y1) * 0.65
        small.append([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2, 0.9])
    dets = [np.array(small)]
    aps = coco_aps(gt, dets)
    assert aps["ap50"] == pytest.approx(0.0) and aps["ap30"] == pytest.approx(1.0)
    assert box_size_ratios(gt, dets) == pytest.approx((0.65, 0.65))
    assert coco_aps(gt, [np.array([[0.0, 0.0, 10.0, 10.0, 0.9]])])["ap30"] == pytest.approx(0.0)
    assert np.isnan(box_size_ratios(gt, [np.zeros((0, 5))])).all()
