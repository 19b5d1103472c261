"""Training of the sky model (``streetaug train-sky``) and of the image predictor (``streetaug train-light``).

Both are reproducible for a seed and a thread count (same data, same batches, same initialisation);
checkpoints (model + optimiser + RNG state) are written every ``ckpt_every`` steps into the cache
folder and a rerun with the same configuration resumes from the last one.  The learning rate follows a
cosine decay over ``steps``.  Data: :mod:`.data` (generated and cached outside the repository).

Losses (paper supplement), all on the log encoding ``log1p``:

* sky model: L1 angular error of the peak direction + L2 of ``log1p`` peak intensity + L2 of the
  ``log1p`` HDR dome (weighted up around the true peak); teacher forcing: every other step the decoder
  gets the true direction, and always the true intensity (the encoder's intensity is trained by its own
  loss), with the predicted latent.
* image predictor: L1 angular error of the sun direction (sunny targets only), cross-entropy of the
  predicted direction distribution (dome cells) against a ~7 deg lobe around the true peak (all targets:
  it learns to spread out when the sky gives no evidence), binary cross-entropy of the sun visibility, L2 of the
  ``log1p`` intensity, L1 of the latent (targets from the frozen sky encoder), and L2 of the ``log1p``
  dome decoded by the frozen sky decoder.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from ..core import InputError, atomic_path, read_image_rgb, write_json_atomic
from ..lighting.skynet.inputs import VIEW_SIZE
from .data import (
    PANORAMA_SUN_VISIBILITY,
    TRAIN_PANORAMAS,
    VAL_PANORAMAS,
    SkyBatches,
    default_cache_dir,
    crop_view_pool,
    default_hdri_dir,
    dome_batch,
    flip_view,
    expose_dome,
    panorama_visibility,
    load_panoramas,
    panorama_view,
    street_view_pool,
    synthetic_sky_pool,
    views_batch,
)
from .real import HELDOUT_PANORAMAS, TRAIN_KEYFRAMES, TRAIN_PANORAMAS_V3, jitter_photo, photo_view, street_photos
from ..lighting.skynet.dome import angle_deg, find_peak, panorama_to_dome
from ..lighting.skynet.model import LightNet, LightNetConfig, SkyModel, SkyNetConfig, count_parameters
from ..lighting.skynet.weights import (
    LIGHT_VERSION,
    LIGHT_WEIGHTS,
    SKY_WEIGHTS,
    load_light_model,
    load_sky_model,
    packaged_weights,
    save_weights,
)

SUNNY_VISIBILITY = 0.2  # views whose sun visibility exceeds this supervise the direction with the L1 loss
PEAK_LOSS_WEIGHT = 20.0  # extra HDR-loss weight at the sky model's true peak
TARGET_KAPPA = 60.0  # width (~7 deg) of the soft target of the image predictor's direction distribution


@dataclass(frozen=True)
class TrainConfig:
    """Options both trainings share (``streetaug train-sky`` / ``train-light``)."""

    seed: int = 0
    steps: int = 1000
    batch: int = 12
    lr: float = 1e-3
    threads: int = 1  # more torch threads than free cores make OpenMP spin (5-10x slower on a shared machine)
    ckpt_every: int = 50
    val_every: int = 100
    out: str | None = None  # weights file (default: the package's)
    cache_dir: str | None = None
    hdri_dir: str | None = None


@dataclass(frozen=True)
class SkyTrainConfig(TrainConfig):
    """``streetaug train-sky`` options."""

    n_synth: int = 3000
    real_fraction: float = 0.3
    height: int = 32
    width: int = 128


@dataclass(frozen=True)
class LightTrainConfig(TrainConfig):
    """``streetaug train-light`` options."""

    steps: int = 8000  # v1 (1600 steps at lr 1e-3) barely left the uniform direction distribution
    batch: int = 16
    lr: float = 2e-3
    n_streets: int = 600  # x 2 rendered views
    n_crops: int = 3000  # half real-panorama crops, half synthetic-sky crops
    mix: tuple[float, ...] = (0.5, 0.25, 0.25, 0.0)  # street renders, panorama crops, synthetic sky crops, real photos
    sky_weights: str | None = None
    init_weights: str | None = None  # fine-tune from these image-predictor weights (None: from scratch)
    train_panoramas: tuple[str, ...] = TRAIN_PANORAMAS  # panoramas the crops are cut from
    val_panoramas: tuple[str, ...] = VAL_PANORAMAS  # logged during training (never used to choose anything)
    real_dataroot: str | None = None  # nuScenes folder of the real street photos (mix[3] > 0)
    real_keyframes: tuple[int, ...] = TRAIN_KEYFRAMES  # keyframes of the dev scene trained on
    version: int = LIGHT_VERSION  # written into the weights file


# The shipped image predictor v3: v2 fine-tuned on the dev scene's training keyframes, crops of 11 panoramas
# (the 4 of v2 + 7 of the 11 new ones) and v2's synthetic pools (see MODEL_CARD.md).
LIGHT_V3 = LightTrainConfig(
    steps=1600, batch=16, lr=5e-4, val_every=400, n_streets=150, mix=(0.25, 0.3, 0.1, 0.35),
    init_weights=None,  # v2's weights file (git history: e6b26cc augment/lighting/skynet/weights/light_model_v2.pt)
    train_panoramas=TRAIN_PANORAMAS_V3, val_panoramas=HELDOUT_PANORAMAS,
    real_dataroot=str(default_hdri_dir().parent / "nuscenes-seq"), version=3)


def _config_hash(cfg) -> str:
    d = {k: v for k, v in asdict(cfg).items() if k not in ("out", "cache_dir", "threads", "val_every", "ckpt_every")}
    return hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:12]


def _lr(cfg_lr: float, step: int, steps: int, warmup: int = 30) -> float:
    """Learning rate at ``step``: linear warm-up, then cosine decay to 2 %.  A Python float: a numpy scalar in the
    optimiser state would make the checkpoint unreadable with ``torch.load(weights_only=True)``."""
    if step < warmup:
        return float(cfg_lr * (step + 1) / warmup)
    return float(cfg_lr * (0.02 + 0.98 * 0.5 * (1 + np.cos(np.pi * min(step / max(steps, 1), 1.0)))))


def _angular_l1(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(B,) angle in rad between unit vectors (safe gradient near 0 and pi)."""
    cos = (a * b).sum(dim=1).clamp(-1 + 1e-6, 1 - 1e-6)
    return torch.acos(cos)


def _t(x: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(x))


class _Checkpoint:
    """Model + optimiser + RNG state in the cache folder (written atomically)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def save(self, step: int, model, opt, rng: np.random.Generator, history: list, elapsed: float) -> None:
        payload = {"step": step, "model": model.state_dict(), "opt": opt.state_dict(),
                   "rng": json.dumps(rng.bit_generator.state), "torch_rng": torch.get_rng_state(),
                   "history": json.dumps(history), "elapsed": elapsed}
        with atomic_path(self.path) as tmp:
            torch.save(payload, tmp)

    def load(self, model, opt, rng: np.random.Generator) -> tuple[int, list, float]:
        if not self.path.is_file():
            return 0, [], 0.0
        p = torch.load(self.path, map_location="cpu", weights_only=True)
        model.load_state_dict(p["model"])
        opt.load_state_dict(p["opt"])
        rng.bit_generator.state = json.loads(p["rng"])
        torch.set_rng_state(p["torch_rng"])
        return int(p["step"]), json.loads(p["history"]), float(p["elapsed"])


def _optimise(model: torch.nn.Module, cfg, rng: np.random.Generator, ckpt: _Checkpoint, next_batch, losses_at,
              validate, describe, log) -> tuple[list, float]:
    """The loop both models train with: Adam under :func:`_lr`, gradients clipped at 5, running means of the
    losses (``"dir"`` in degrees), validation every ``cfg.val_every`` steps, resumable checkpoints.

    Args:
        next_batch: () -> dict of tensors; losses_at: (step, batch) -> dict of scalar losses with ``"total"``;
        validate: () -> validation dict; describe: (running, validation) -> a log line.

    Returns:
        The history (one entry per validation) and the training seconds (over resumptions).
    """
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    start, history, elapsed0 = ckpt.load(model, opt, rng)
    if start:
        log(f"resuming from step {start} ({ckpt.path})")
    t0 = time.perf_counter() - elapsed0
    running: dict[str, float] = {}
    for step in range(start, cfg.steps):
        for g in opt.param_groups:
            g["lr"] = _lr(cfg.lr, step, cfg.steps)
        losses = losses_at(step, next_batch())
        opt.zero_grad()
        losses["total"].backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 5.0)
        opt.step()
        for k, v in losses.items():
            v = float(np.degrees(v.item())) if k == "dir" else v.item()
            running[k] = 0.9 * running.get(k, v) + 0.1 * v
        done = step + 1
        if done % cfg.val_every == 0 or done == cfg.steps:
            val = validate()
            history.append({"step": done, "time_s": time.perf_counter() - t0, "train": dict(running), "val": val})
            log(f"step {done}: {describe(running, val)} ({time.perf_counter() - t0:.0f} s)")
        if done % cfg.ckpt_every == 0 or done == cfg.steps:
            ckpt.save(done, model, opt, rng, history, time.perf_counter() - t0)
    return history, time.perf_counter() - t0


# ----------------------------------------------------------------------------- sky model


def sky_validation(model: SkyModel, panoramas: dict[str, np.ndarray], yaws_deg=(0, 90, 180, 270)) -> dict:
    """Reconstruction of domes of ``panoramas`` (median-exposed): log-MSE and decoded-peak angular error
    vs the peak of the true dome, per panorama and overall."""
    cfg = model.cfg
    out: dict = {}
    errs, mses = [], []
    model.eval()
    with torch.no_grad():
        for name, pano in panoramas.items():
            domes = [expose_dome(panorama_to_dome(pano, cfg.height, cfg.width, np.radians(y)), None) for y in yaws_deg]
            b = dome_batch(domes)
            li, d, z = model.encoder(_t(b["ldr"]))
            y = model.decoder(li, d, z)
            mse = ((y - _t(b["log_hdr"])) ** 2).mean(dim=(1, 2, 3)).numpy()
            rec = np.expm1(np.maximum(y.numpy(), 0.0)).transpose(0, 2, 3, 1)
            e = [float(angle_deg(find_peak(r), t)) for r, t in zip(rec, b["dir"])]
            out[name] = {"log_mse": float(mse.mean()), "peak_err_deg_median": float(np.median(e))}
            errs += e
            mses += mse.tolist()
    model.train()
    out["all"] = {"log_mse": float(np.mean(mses)), "peak_err_deg_median": float(np.median(errs))}
    return out


def peak_weights(decoder, direction: torch.Tensor) -> torch.Tensor:
    """(B, 1, H, W) HDR-loss weights ``1 + PEAK_LOSS_WEIGHT x lobe`` around the true peak (a few pixels
    out of thousands would otherwise barely count)."""
    cos = (decoder.pe * direction[:, :, None, None]).sum(dim=1, keepdim=True)
    return 1.0 + PEAK_LOSS_WEIGHT * torch.exp(4.0 * decoder.cfg.kappa * (cos - 1.0))


def train_sky(cfg: SkyTrainConfig, log=print) -> dict:
    """Train the sky model; writes the weights (``cfg.out`` or the package's) and returns a report."""
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    cache = Path(cfg.cache_dir or default_cache_dir())
    hdri = Path(cfg.hdri_dir or default_hdri_dir())
    t_data = time.perf_counter()
    panos = load_panoramas(hdri, TRAIN_PANORAMAS)
    val_panos = load_panoramas(hdri, VAL_PANORAMAS)
    synth, _ = synthetic_sky_pool(cfg.n_synth, cfg.seed, cfg.height, cfg.width, cache, workers=cfg.threads, log=log)
    data = SkyBatches(synth, panos, cfg.height, cfg.width, cfg.real_fraction)
    t_data = time.perf_counter() - t_data
    net_cfg = SkyNetConfig(height=cfg.height, width=cfg.width)
    model = SkyModel(net_cfg)

    def losses_at(step: int, b: dict) -> dict:
        log_int, direction, latent = model.encoder(b["ldr"])
        l_dir = _angular_l1(direction, b["dir"]).mean()
        l_int = ((log_int - b["log_int"]) ** 2).mean()
        # teacher forcing: every other step the true direction; the true intensity always (an LDR dome
        # barely constrains the sun's intensity, and a decoder fed noisy intensities learns to ignore them)
        y = model.decoder(b["log_int"], b["dir"] if step % 2 == 1 else direction, latent)
        l_hdr = (peak_weights(model.decoder, b["dir"]) * (y - b["log_hdr"]) ** 2).mean()
        return {"total": l_dir + l_int + l_hdr, "dir": l_dir, "int": l_int, "hdr": l_hdr}

    def describe(running: dict, val: dict) -> str:
        return (f"train dir {running['dir']:.1f} deg int {running['int']:.3f} hdr {running['hdr']:.4f} | "
                f"val log-MSE {val['all']['log_mse']:.4f} peak {val['all']['peak_err_deg_median']:.2f} deg")

    log(f"sky model: {count_parameters(model)} parameters, {cfg.steps} steps of {cfg.batch}")
    history, train_s = _optimise(
        model, cfg, rng, _Checkpoint(cache / f"ckpt_sky_{_config_hash(cfg)}.pt"),
        lambda: {k: _t(v) for k, v in data.batch(cfg.batch, rng).items()}, losses_at,
        lambda: sky_validation(model, val_panos), describe, log)
    val = sky_validation(model, val_panos)
    report = {
        "kind": "sky", "config": asdict(cfg), "architecture": net_cfg.to_dict(), "parameters": count_parameters(model),
        "train_time_s": train_s, "data_time_s": t_data, "threads": cfg.threads,
        "train_panoramas": list(TRAIN_PANORAMAS), "val_panoramas": list(VAL_PANORAMAS),
        "val": val, "history": history, "torch": torch.__version__,
    }
    out = Path(cfg.out) if cfg.out else packaged_weights(SKY_WEIGHTS)
    save_weights(out, model, "sky", 1, net_cfg.to_dict(), {k: report[k] for k in report if k != "history"})
    write_json_atomic(cache / f"report_sky_{_config_hash(cfg)}.json", report)
    log(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB) after {train_s / 60:.1f} min")
    return report


# ----------------------------------------------------------------------------- image predictor


def soft_direction_targets(target: torch.Tensor, bin_dirs: torch.Tensor, bin_omega: torch.Tensor,
                           kappa: float = TARGET_KAPPA) -> torch.Tensor:
    """(B, n_bins) target distribution: a spherical Gaussian lobe of concentration ``kappa`` around each unit
    ``target`` (B, 3), integrated over the bins (weights = solid angles)."""
    w = torch.exp(kappa * (target @ bin_dirs.T - 1.0)) * bin_omega[None]
    return w / w.sum(dim=1, keepdim=True).clamp(min=1e-12)


@dataclass
class LightBatches:
    """Random batches of views for the image predictor from up to four pools (street renders, real-panorama
    crops, synthetic-sky crops, real street photos) mixed by ``mix``; each view is mirrored with probability
    1/2, and a real photo is first randomly cropped and re-exposed (:func:`.real.jitter_photo`)."""

    pools: tuple[list, ...]
    mix: tuple[float, ...]
    dome_hw: tuple[int, int] = (32, 128)

    def batch(self, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        p = np.array([m if len(pool) else 0.0 for m, pool in zip(self.mix, self.pools)], dtype=np.float64)
        p = p / p.sum()
        views = []
        for _ in range(n):
            k = int(rng.choice(len(p), p=p))
            v = self.pools[k][int(rng.integers(len(self.pools[k])))]
            if k == 3:
                v = jitter_photo(v, rng, VIEW_SIZE)
            views.append(flip_view(v) if rng.uniform() < 0.5 else v)
        return views_batch(views, self.dome_hw)


def light_losses(net: LightNet, sky: SkyModel, b: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The image predictor's loss terms on one batch (see module doc).  Real photos (``has_dome`` 0) have
    only a sun: their direction is supervised (L1 and cross-entropy, whatever the visibility: the ephemeris
    knows it) and their visibility; the intensity, latent and dome terms skip them."""
    o = net(b["ldr"], b["rays"])
    has = b["has_dome"] if "has_dome" in b else torch.ones_like(b["vis"])
    n_dome = has.sum().clamp(min=1.0)
    with torch.no_grad():
        _, _, latent_t = sky.encoder(b["dome_ldr"])
    sunny = ((b["vis"] > SUNNY_VISIBILITY) | (has < 0.5)).float()
    l_dir = (_angular_l1(o["dir"], b["dir"]) * sunny).sum() / sunny.sum().clamp(min=1.0)
    q = soft_direction_targets(b["dir"], net.bin_dirs, net.bin_omega)
    l_ce = -(q * o["dir_logp"]).sum(dim=1).mean()
    l_vis = F.binary_cross_entropy_with_logits(o["vis_logit"], b["vis"])
    l_int = (((o["log_int"] - b["log_int"]) ** 2).mean(dim=1) * has).sum() / n_dome
    l_lat = ((o["latent"] - latent_t).abs().mean(dim=1) * has).sum() / n_dome
    y = sky.decoder(o["log_int"], o["dir"], o["latent"])
    l_hdr = (((y - b["log_hdr"]) ** 2).mean(dim=(1, 2, 3)) * has).sum() / n_dome
    total = l_dir + l_ce + l_vis + 0.25 * l_int + 0.5 * l_lat + l_hdr
    return {"total": total, "dir": l_dir, "ce": l_ce, "vis": l_vis, "int": l_int, "lat": l_lat, "hdr": l_hdr}


def real_photo_pool(dataroot: str | Path | None, keyframes: tuple[int, ...], cache_dir: str | Path, log=print) -> list:
    """Training views (:func:`.real.photo_view`) of the dev scene's ``keyframes`` with ephemeris sun labels and
    shadow-evidence visibilities; cached as one ``.npz`` (outside the repository: the images are CC BY-NC-SA)."""
    from .data import View
    from .real import DEV_SCENE

    if dataroot is None or not Path(dataroot).is_dir():
        raise InputError(f"{dataroot}: real street photos folder not found (the nuScenes dev scene; set real_dataroot)")
    tag = hashlib.sha256(json.dumps([str(Path(dataroot).resolve()), list(keyframes), "control-v1"]).encode()).hexdigest()[:10]
    cache = Path(cache_dir) / f"real_photos_{DEV_SCENE}_{tag}.npz"
    if cache.is_file():
        with np.load(cache) as z:
            ldr, K, R, vis, sun = (z[k] for k in ("ldr", "K", "R", "vis", "sun"))
        return [View(ldr[i], K[i], R[i], None, float(vis[i]), sun[i]) for i in range(len(vis))]
    log(f"reading {len(keyframes)} keyframes of {DEV_SCENE} (sun labels, object shadows) -> {cache}")
    photos = street_photos(dataroot, keyframes=keyframes, shadows=True)
    views = [photo_view(p, read_image_rgb(p.image_path)) for p in photos]
    cache.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(cache) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, ldr=np.stack([v.ldr for v in views]), K=np.stack([v.K for v in views]),
                     R=np.stack([v.R_heading_from_cam for v in views]),
                     vis=np.array([v.visibility for v in views], np.float32),
                     sun=np.stack([v.sun_dir_heading for v in views]),
                     contrast=np.array([np.nan if p.shadow_contrast is None else p.shadow_contrast for p in photos]))
    return views


def light_validation(net: LightNet, panoramas: dict[str, np.ndarray], dome_hw: tuple[int, int], seed: int = 12345,
                     per_pano: int = 8) -> dict:
    """Sun-direction error (deg) on fixed random crops of ``panoramas`` whose sun is visible."""
    rng = np.random.default_rng(seed)
    visibility = panorama_visibility()
    errs = []
    net.eval()
    with torch.no_grad():
        for name, pano in panoramas.items():
            if visibility[name] < 0.5:
                continue
            views = [panorama_view(pano, 1.0, rng, dome_hw) for _ in range(per_pano)]
            b = views_batch(views)
            o = net(_t(b["ldr"]), _t(b["rays"]))
            errs += angle_deg(o["dir"].numpy(), b["dir"]).tolist()
    net.train()
    return {"sun_err_deg_median": float(np.median(errs)) if errs else None, "n": len(errs)}


def train_light(cfg: LightTrainConfig, log=print) -> dict:
    """Train the image -> sky-vector predictor on top of the frozen sky model; writes its weights."""
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    cache = Path(cfg.cache_dir or default_cache_dir())
    hdri = Path(cfg.hdri_dir or default_hdri_dir())
    sky = load_sky_model(cfg.sky_weights)
    for p in sky.parameters():
        p.requires_grad_(False)
    dome_hw = (sky.cfg.height, sky.cfg.width)
    t_data = time.perf_counter()
    val_panos = load_panoramas(hdri, cfg.val_panoramas)
    mix = tuple(cfg.mix) + (0.0,) * (4 - len(cfg.mix))
    street = street_view_pool(cfg.n_streets, cfg.seed, dome_hw, cache, workers=cfg.threads, log=log) if mix[0] > 0 else []
    pano_crops, sky_crops = crop_view_pool(cfg.n_crops, cfg.seed, dome_hw, hdri, cache, workers=cfg.threads, log=log,
                                           panoramas=tuple(cfg.train_panoramas))
    photos = real_photo_pool(cfg.real_dataroot, tuple(cfg.real_keyframes), cache, log) if mix[3] > 0 else []
    t_data = time.perf_counter() - t_data
    data = LightBatches((street, pano_crops, sky_crops, photos), mix, dome_hw)
    if cfg.init_weights:
        init = cfg.init_weights
        init = packaged_weights(init.removeprefix("packaged:")) if init.startswith("packaged:") else Path(init)
        net = load_light_model(init).train()
        net_cfg = net.cfg
        log(f"fine-tuning {init}")
    else:
        net_cfg = LightNetConfig()
        net = LightNet(net_cfg)
    log(f"image predictor: {count_parameters(net)} parameters, {len(street)} street views, {len(pano_crops)} panorama "
        f"crops, {len(photos)} real photos, {cfg.steps} steps of {cfg.batch}")
    history, train_s = _optimise(
        net, cfg, rng, _Checkpoint(cache / f"ckpt_light_{_config_hash(cfg)}.pt"),
        lambda: {k: _t(v) for k, v in data.batch(cfg.batch, rng).items()}, lambda step, b: light_losses(net, sky, b),
        lambda: light_validation(net, val_panos, dome_hw),
        lambda running, val: " ".join(f"{k} {v:.3f}" for k, v in running.items())
        + f" | val sun {val['sun_err_deg_median']:.1f} deg", log)
    report = {
        "kind": "light", "config": asdict(cfg), "architecture": net_cfg.to_dict(), "parameters": count_parameters(net),
        "train_time_s": train_s, "data_time_s": t_data, "threads": cfg.threads, "street_views": len(street),
        "real_photos": len(photos), "train_panoramas": list(cfg.train_panoramas), "val_panoramas": list(cfg.val_panoramas),
        "val": light_validation(net, val_panos, dome_hw), "history": history, "torch": torch.__version__,
    }
    out = Path(cfg.out) if cfg.out else packaged_weights(LIGHT_WEIGHTS)
    save_weights(out, net, "light", cfg.version, net_cfg.to_dict(), {k: report[k] for k in report if k != "history"})
    write_json_atomic(cache / f"report_light_{_config_hash(cfg)}.json", report)
    log(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB) after {train_s / 60:.1f} min")
    return report
