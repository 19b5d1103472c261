"""The networks: the sky model (encoder + peak-aware UNet decoder) and the image -> sky-vector predictor.

Sky vector ``f`` (64 floats, the paper's layout): ``[f_intensity (3), f_dir (3), f_latent (58)]``.
Inside the networks the intensity is carried as ``log1p(f_intensity)`` (linear HDR RGB of the peak
pixel on the dome's radiometric scale); ``f_dir`` is a unit vector in the heading frame (see
:mod:`.dome`).  Decoded domes are ``log1p(HDR)`` maps (the paper's log encoding), (B, 3, H, W).

Decoder input (7 channels, paper supplement): peak-direction encoding ``exp(kappa (u . f_dir - 1))``,
peak-intensity encoding (``log1p(f_intensity)`` where the direction encoding >= 0.98, else 0) and the
3-channel positional encoding (the unit direction ``u`` of each pixel).  Unlike the paper, the peak is
also added to the output as a bilinear splat (a residual): trained for ~1000 steps, the UNet blurred it
~8x below ``f_intensity``.  The paper's ``kappa = 100``
is for 64 x 256 domes; it is scaled with the pixel size (``kappa = 100 (H / 64)^2``) so the lobe and
the 0.98 disc keep their size in pixels at other resolutions.  The latent is fused at the bottleneck.

Panorama convolutions pad circularly in longitude and with zeros in latitude.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from .dome import dome_directions, dome_solid_angles

LATENT_DIM = 58
SKY_VECTOR_DIM = 64
PEAK_DISC_THRESHOLD = 0.98


@dataclass(frozen=True)
class SkyNetConfig:
    """Architecture of the sky model (stored with the weights)."""

    height: int = 32
    width: int = 128
    enc_channels: tuple[int, ...] = (16, 32, 64, 64, 64)
    dec_down: tuple[int, ...] = (16, 32, 64, 64, 64)
    dec_up: tuple[int, ...] = (64, 32, 16, 16, 8)
    latent_dim: int = LATENT_DIM

    @property
    def kappa(self) -> float:
        return 100.0 * (self.height / 64.0) ** 2

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @staticmethod
    def from_dict(d: dict) -> "SkyNetConfig":
        return SkyNetConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})


@dataclass(frozen=True)
class LightNetConfig:
    """Architecture of the image -> sky-vector predictor (stored with the weights)."""

    height: int = 96
    width: int = 160
    channels: tuple[int, ...] = (24, 32, 64, 96, 128)
    hidden: int = 256
    dir_bins: tuple[int, int] = (16, 64)  # heading-frame dome cells of the direction distribution
    latent_dim: int = LATENT_DIM

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @staticmethod
    def from_dict(d: dict) -> "LightNetConfig":
        return LightNetConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})


# ----------------------------------------------------------------------------- building blocks


class PanoConv(nn.Module):
    """3x3 convolution on an equirect map: circular padding in width (longitude), zeros in height."""

    def __init__(self, c_in: int, c_out: int, stride: int = 1, pano: bool = True) -> None:
        super().__init__()
        self.pano = pano
        self.conv = nn.Conv2d(c_in, c_out, 3, stride=stride, padding=(1, 0) if pano else 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv(F.pad(x, (1, 1, 0, 0), mode="circular") if self.pano else x)


def _norm(c: int) -> nn.GroupNorm:
    return nn.GroupNorm(min(8, c // 4) if c >= 8 else 1, c)


class ResBlock(nn.Module):
    """conv-norm-act-conv-norm + (projected) skip, then act; ``stride`` 2 halves the map."""

    def __init__(self, c_in: int, c_out: int, stride: int = 1, pano: bool = True) -> None:
        super().__init__()
        self.c1 = PanoConv(c_in, c_out, stride, pano)
        self.n1 = _norm(c_out)
        self.c2 = PanoConv(c_out, c_out, 1, pano)
        self.n2 = _norm(c_out)
        self.skip = None
        if stride != 1 or c_in != c_out:
            self.skip = nn.Conv2d(c_in, c_out, 1, stride=stride)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = F.silu(self.n1(self.c1(x)))
        h = self.n2(self.c2(h))
        return F.silu(h + (x if self.skip is None else self.skip(x)))


def positional_encoding(height: int, width: int) -> torch.Tensor:
    """(1, 3, H, W) unit direction of every dome pixel (heading frame)."""
    d = torch.from_numpy(np.array(dome_directions(height, width), dtype=np.float32))
    return d.permute(2, 0, 1)[None].contiguous()


# ----------------------------------------------------------------------------- sky model


class _Branch(nn.Module):
    def __init__(self, c_in: int, channels: tuple[int, ...], n_out: int) -> None:
        super().__init__()
        blocks, c = [], c_in
        for co in channels:
            blocks.append(ResBlock(c, co, stride=2))
            c = co
        self.blocks = nn.Sequential(*blocks)
        self.head = nn.Sequential(nn.Linear(2 * c, 2 * c), nn.SiLU(), nn.Linear(2 * c, n_out))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.blocks(x)
        return self.head(torch.cat([h.mean(dim=(2, 3)), h.amax(dim=(2, 3))], dim=1))


class _PeakBranch(nn.Module):
    """Peak CNN: intensity from pooled deep features; direction as a spatial soft-argmax: per-pixel logits
    (from the input and the first two feature maps, upsampled) -> softmax -> weighted mean of the pixels'
    unit directions (translation-invariant pooling alone cannot say *where* the peak is)."""

    def __init__(self, cfg: SkyNetConfig) -> None:
        super().__init__()
        blocks, c = [], 6
        for co in cfg.enc_channels:
            blocks.append(ResBlock(c, co, stride=2))
            c = co
        self.blocks = nn.ModuleList(blocks)
        c_att = 6 + cfg.enc_channels[0] + cfg.enc_channels[1]
        self.attention = nn.Sequential(PanoConv(c_att, 16), nn.SiLU(), nn.Conv2d(16, 1, 1))
        self.head = nn.Sequential(nn.Linear(2 * c, 2 * c), nn.SiLU(), nn.Linear(2 * c, 3))

    def forward(self, x: torch.Tensor, pe: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h, feats = x, []
        for block in self.blocks:
            h = block(h)
            feats.append(h)
        size = x.shape[2:]
        up = [F.interpolate(f, size=size, mode="bilinear", align_corners=False) for f in feats[:2]]
        logits = self.attention(torch.cat([x, *up], dim=1)).flatten(1)
        w = torch.softmax(logits, dim=1)
        direction = F.normalize((pe.flatten(2) * w[:, None]).sum(-1), dim=1, eps=1e-6)
        log_int = F.softplus(self.head(torch.cat([h.mean(dim=(2, 3)), h.amax(dim=(2, 3))], dim=1)))
        return log_int, direction


class SkyEncoder(nn.Module):
    """LDR dome (B, 3, H, W) in [0, 1] -> (log1p intensity (B, 3), unit direction (B, 3), latent (B, 58))."""

    def __init__(self, cfg: SkyNetConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.register_buffer("pe", positional_encoding(cfg.height, cfg.width), persistent=False)
        self.peak = _PeakBranch(cfg)
        self.latent = _Branch(6, cfg.enc_channels, cfg.latent_dim)

    def forward(self, ldr: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        pe = self.pe.expand(len(ldr), -1, -1, -1)
        x = torch.cat([ldr * 2.0 - 1.0, pe], dim=1)
        log_int, direction = self.peak(x, pe)
        return log_int, direction, self.latent(x)


class SkyDecoder(nn.Module):
    """Sky vector -> log1p HDR dome (B, 3, H, W): a UNet on the 7-channel peak + position encoding."""

    def __init__(self, cfg: SkyNetConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.register_buffer("pe", positional_encoding(cfg.height, cfg.width), persistent=False)
        omega = np.array(dome_solid_angles(cfg.height, cfg.width)[:, 0], dtype=np.float32)
        self.register_buffer("row_omega", torch.from_numpy(omega), persistent=False)
        # full-resolution stages are single convolutions (most of the cost lives there)
        self.stem = nn.Sequential(PanoConv(7, cfg.dec_down[0]), nn.SiLU())
        downs, c = [], cfg.dec_down[0]
        for co in cfg.dec_down:
            downs.append(ResBlock(c, co, stride=2))
            c = co
        self.downs = nn.ModuleList(downs)
        hb, wb = cfg.height // 2 ** len(cfg.dec_down), cfg.width // 2 ** len(cfg.dec_down)
        self.bottleneck_shape = (c, hb, wb)
        self.fuse_latent = nn.Linear(cfg.latent_dim, c * hb * wb)
        self.mid = ResBlock(2 * c, c)
        skips = [cfg.dec_down[0]] + list(cfg.dec_down[:-1])  # channels of the map each up-step lands on
        ups = []
        for k, (co, cs) in enumerate(zip(cfg.dec_up, reversed(skips))):
            last = k == len(cfg.dec_up) - 1
            ups.append(nn.Sequential(PanoConv(c + cs, co), nn.SiLU()) if last else ResBlock(c + cs, co))
            c = co
        self.ups = nn.ModuleList(ups)
        self.out = nn.Conv2d(c + 7, 3, 1)

    def encodings(self, log_int: torch.Tensor, direction: torch.Tensor) -> torch.Tensor:
        """(B, 7, H, W): peak-direction lobe, peak-intensity disc, positional encoding."""
        pe = self.pe.expand(len(direction), -1, -1, -1)
        cos = (pe * direction[:, :, None, None]).sum(dim=1, keepdim=True)
        lobe = torch.exp(self.cfg.kappa * (cos - 1.0))
        disc = (lobe >= PEAK_DISC_THRESHOLD).float() * log_int[:, :, None, None]
        return torch.cat([lobe, disc, pe], dim=1)

    def forward(self, log_int: torch.Tensor, direction: torch.Tensor, latent: torch.Tensor) -> torch.Tensor:
        x0 = self.encodings(log_int, direction)
        h = self.stem(x0)
        feats = [h]
        for down in self.downs:
            h = down(h)
            feats.append(h)
        z = self.fuse_latent(latent).view(len(latent), *self.bottleneck_shape)
        h = self.mid(torch.cat([h, z], dim=1))
        for up, skip in zip(self.ups, reversed(feats[:-1])):
            h = F.interpolate(h, size=skip.shape[2:], mode="bilinear", align_corners=False)
            h = up(torch.cat([h, skip], dim=1))
        # the peak itself is added to the output as a bilinear splat at f_dir (the brightest of its 4 pixels
        # = f_intensity): the UNet decodes the sky around it instead of re-learning an extreme, sub-pixel peak
        # (its position is detached: a log-space splat's gradient in the direction is huge and useless; the
        # direction learns through the encodings)
        return self.out(torch.cat([h, x0], dim=1)) + self.peak_splat(log_int, direction.detach())

    def peak_splat(self, log_int: torch.Tensor, direction: torch.Tensor) -> torch.Tensor:
        """(B, 3, H, W) ``log1p(f_intensity x w / max w)``: w = bilinear weight of the 4 pixel centres around
        ``direction`` / pixel solid angle (the radiance of a point source spread energy-preservingly, as
        :func:`.synth.splat_direction`); longitude wraps, latitude is clamped to the dome."""
        H, W = self.cfg.height, self.cfg.width
        lon = torch.atan2(direction[:, 1], direction[:, 0])
        lat = torch.asin(direction[:, 2].clamp(0.0, 1.0))
        x = (lon / (2 * np.pi) + 0.5) * W - 0.5
        y = ((1.0 - lat / (np.pi / 2)) * H - 0.5).clamp(0.0, H - 1.0)
        cols = torch.arange(W, dtype=x.dtype, device=x.device)
        rows = torch.arange(H, dtype=x.dtype, device=x.device)
        dx = torch.remainder(cols[None] - x[:, None] + W / 2, W) - W / 2  # wrapped column offset
        wx = (1.0 - dx.abs()).clamp(min=0.0)
        wy = (1.0 - (rows[None] - y[:, None]).abs()).clamp(min=0.0)
        w = wy[:, :, None] * wx[:, None, :] / self.row_omega[None, :, None]  # radiance of an energy splat
        w = w / w.flatten(1).amax(dim=1).clamp(min=1e-12)[:, None, None]
        return torch.log1p(torch.expm1(log_int)[:, :, None, None] * w[:, None])


class SkyModel(nn.Module):
    """Encoder + decoder of the sky (the paper's sky modelling network, scaled for CPUs)."""

    def __init__(self, cfg: SkyNetConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg or SkyNetConfig()
        self.encoder = SkyEncoder(self.cfg)
        self.decoder = SkyDecoder(self.cfg)


# ----------------------------------------------------------------------------- image -> sky vector


class LightNet(nn.Module):
    """LDR image (B, 3, h, w) + per-pixel heading-frame rays (B, 3, h, w) -> sky-vector prediction.

    The rays are fed to every stage (so the net knows the field of view and the horizon); features are
    pooled by mean and by a learned attention.  The peak direction is a probability distribution over
    ``dir_bins`` cells of the heading-frame dome, a mixture of (a) a global head (the sky's gradient,
    shadows: the sun out of view) and (b) an attention over the image's own pixels, binned by their rays
    (the sun in view), weighted by a learned "in view" probability.  Classifying directions learns far
    better than regressing a unit vector and says how sure the net is.

    Outputs: ``dir`` (B, 3) unit direction (mixture of the global mean and the attended rays),
    ``dir_logp`` (B, n_bins) log-probabilities of the cells, ``log_int`` (B, 3), ``vis_logit`` (B,) sun
    visibility, ``latent`` (B, 58).
    """

    def __init__(self, cfg: LightNetConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg = cfg or LightNetConfig()
        blocks, c = [], 6
        for co in cfg.channels:
            blocks.append(ResBlock(c + 3, co, stride=2, pano=False))
            c = co
        self.blocks = nn.ModuleList(blocks)
        self.attn = nn.Conv2d(c + 3, 1, 1)
        self.pixel_attn = nn.Sequential(nn.Conv2d(cfg.channels[1] + 3, 16, 3, padding=1), nn.SiLU(), nn.Conv2d(16, 1, 1))
        self.trunk = nn.Sequential(nn.Linear(2 * (c + 3), cfg.hidden), nn.SiLU())
        hb, wb = cfg.dir_bins
        self.register_buffer("bin_dirs", positional_encoding(hb, wb).flatten(2)[0].T.contiguous(), persistent=False)
        omega = torch.from_numpy(np.array(dome_solid_angles(hb, wb), dtype=np.float32)).flatten()
        self.register_buffer("bin_omega", omega, persistent=False)
        self.dir_head = nn.Linear(cfg.hidden, hb * wb)
        self.head = nn.Linear(cfg.hidden, 3 + 1 + 1 + cfg.latent_dim)

    def _bin_index(self, rays: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Dome-cell index (B, N) and above-horizon mask (B, N) of unit rays (B, 3, N)."""
        hb, wb = self.cfg.dir_bins
        lon = torch.atan2(rays[:, 1], rays[:, 0])
        lat = torch.asin(rays[:, 2].clamp(-1.0, 1.0))
        j = ((1.0 - lat / (np.pi / 2)) * hb).floor().clamp(0, hb - 1).long()
        i = torch.remainder(((lon / (2 * np.pi) + 0.5) * wb).floor(), wb).long()
        return j * wb + i, lat > 0

    def forward(self, ldr: torch.Tensor, rays: torch.Tensor) -> dict[str, torch.Tensor]:
        h = torch.cat([ldr * 2.0 - 1.0, rays], dim=1)
        feats = []
        for block in self.blocks:
            r = F.adaptive_avg_pool2d(rays, h.shape[2:]) if h.shape[2:] != rays.shape[2:] else rays
            h = block(torch.cat([h, r], dim=1))
            feats.append(h)
        r = F.adaptive_avg_pool2d(rays, h.shape[2:])
        h = torch.cat([h, r], dim=1)
        a = torch.softmax(self.attn(h).flatten(1), dim=1)
        pooled = torch.cat([h.mean(dim=(2, 3)), (h.flatten(2) * a[:, None]).sum(-1)], dim=1)
        t = self.trunk(pooled)
        o = self.head(t)
        # (a) global distribution over the dome cells
        p_global = torch.softmax(self.dir_head(t), dim=1)
        # (b) attention over the image's pixels (above the horizon), binned by their rays
        f1 = feats[1]
        r1 = F.normalize(F.adaptive_avg_pool2d(rays, f1.shape[2:]), dim=1).flatten(2)  # (B, 3, N)
        idx, above = self._bin_index(r1)
        logits_px = self.pixel_attn(torch.cat([f1, r1.view(len(r1), 3, *f1.shape[2:])], dim=1)).flatten(1)
        logits_px = logits_px.masked_fill(~above, -1e4)
        w_px = torch.softmax(logits_px, dim=1) * above
        p_image = torch.zeros_like(p_global).scatter_add(1, idx, w_px)
        in_view = torch.sigmoid(o[:, 4]) * (above.any(dim=1)).float()
        p = (1.0 - in_view[:, None]) * p_global + in_view[:, None] * p_image
        d_global = p_global @ self.bin_dirs
        d_image = (r1 * w_px[:, None]).sum(-1)
        direction = F.normalize((1.0 - in_view[:, None]) * d_global + in_view[:, None] * d_image, dim=1, eps=1e-6)
        return {
            "log_int": F.softplus(o[:, 0:3]),
            "dir": direction,
            "dir_logp": torch.log(p.clamp(min=1e-12)),
            "vis_logit": o[:, 3],
            "latent": o[:, 5:],
        }


def direction_cone_deg(p: np.ndarray, bin_dirs: np.ndarray, direction: np.ndarray, mass: float = 0.68) -> float:
    """Half-angle (deg) of the cone around ``direction`` (3,) holding ``mass`` of a distribution ``p`` (n,)
    over unit ``bin_dirs`` (n, 3)."""
    ang = np.degrees(np.arccos(np.clip(bin_dirs @ direction, -1.0, 1.0)))
    order = np.argsort(ang)
    k = int(np.searchsorted(np.cumsum(p[order]), mass * float(p.sum())))
    return float(ang[order][min(k, len(order) - 1)])


def count_parameters(module: nn.Module) -> int:
    return int(sum(p.numel() for p in module.parameters()))
