"""Saving and loading network weights safely (no pickle of code), with clear errors.

File format ``streetaug.skynet/1``: ``torch.save`` of a plain dict ``{"format", "kind", "version",
"config", "meta", "state_dict", "sha256"}`` holding only strings, numbers, lists, dicts and float16/float32
tensors, read back with ``torch.load(weights_only=True)`` (which refuses arbitrary objects).  Tensors are
stored as float16 (halves the package size) and cast back to float32 on loading; ``sha256`` (over the
tensors' names, shapes, dtypes and bytes) detects corrupted files that still unzip.
"""

from __future__ import annotations

import hashlib
import json
from importlib import resources
from pathlib import Path

import torch
import torch.nn as nn

from ...core import InputError, atomic_path
from .model import LightNet, LightNetConfig, SkyModel, SkyNetConfig

WEIGHTS_FORMAT = "streetaug.skynet/1"
SKY_WEIGHTS = "sky_model_v1.pt"
LIGHT_WEIGHTS = "light_model_v2.pt"
LIGHT_VERSION = 2  # 2: trained 5x longer on views with the camera pitch sign fixed (see MODEL_CARD.md)


def packaged_weights(name: str) -> Path:
    """Path of a weights file shipped in the package (``weights/`` beside this module)."""
    return Path(str(resources.files(__package__).joinpath("weights", name)))


def save_weights(path: str | Path, model: nn.Module, kind: str, version: int, config: dict, meta: dict,
                 half: bool = True) -> None:
    """Atomically write ``model``'s weights with its architecture ``config`` and free-form ``meta``."""
    state = {k: (v.detach().to(torch.float16) if half and v.is_floating_point() else v.detach()).clone()
             for k, v in model.state_dict().items()}
    plain = json.loads(json.dumps({"config": config, "meta": meta}, default=_plain))  # only JSON types inside
    payload = {"format": WEIGHTS_FORMAT, "kind": kind, "version": int(version), **plain, "state_dict": state,
               "sha256": state_checksum(state)}
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)


def state_checksum(state: dict) -> str:
    """sha256 over the names, shapes, dtypes and bytes of a state dict's tensors (sorted by name)."""
    h = hashlib.sha256()
    for name in sorted(state):
        t = state[name].detach().contiguous().cpu()
        h.update(f"{name}|{tuple(t.shape)}|{t.dtype}|".encode())
        h.update(t.view(torch.uint8).numpy().tobytes() if t.numel() else b"")
    return h.hexdigest()


def _plain(o):
    if hasattr(o, "item"):
        return o.item()
    if hasattr(o, "tolist"):
        return o.tolist()
    return str(o)


def read_weights(path: str | Path, kind: str) -> dict:
    """The payload of a weights file of ``kind`` ("sky" | "light"); InputError if it is not one."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: weights file not found")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # corrupt zip, truncated file, pickled objects refused by weights_only
        raise InputError(f"{path}: not a readable streetaug weights file ({type(e).__name__}: "
                         f"{str(e).splitlines()[0][:200]}); re-install the package or re-run the training") from None
    if not isinstance(payload, dict) or payload.get("format") != WEIGHTS_FORMAT:
        got = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise InputError(f"{path}: field 'format' is {got!r}, expected {WEIGHTS_FORMAT!r}")
    if payload.get("kind") != kind:
        raise InputError(f"{path}: field 'kind' is {payload.get('kind')!r}, expected {kind!r} weights")
    if not isinstance(payload.get("state_dict"), dict) or not isinstance(payload.get("config"), dict):
        raise InputError(f"{path}: fields 'state_dict' and 'config' must be dictionaries")
    if not all(isinstance(v, torch.Tensor) for v in payload["state_dict"].values()):
        raise InputError(f"{path}: field 'state_dict' must hold only tensors")
    if payload.get("sha256") != state_checksum(payload["state_dict"]):
        raise InputError(f"{path}: checksum mismatch (field 'sha256'): the weights are corrupted; "
                         "re-install the package or re-run the training")
    return payload


def load_state(model: nn.Module, payload: dict, path: str | Path) -> nn.Module:
    """Copy a payload's tensors into ``model`` (float32); InputError naming the first mismatch."""
    state = payload["state_dict"]
    own = model.state_dict()
    missing = sorted(set(own) - set(state))
    unexpected = sorted(set(state) - set(own))
    if missing or unexpected:
        raise InputError(f"{path}: weights do not match the network: missing {missing[:3]}, unexpected "
                         f"{unexpected[:3]} (file version {payload.get('version')}, config {payload.get('config')})")
    for name, want in own.items():
        got = state[name]
        if not isinstance(got, torch.Tensor) or tuple(got.shape) != tuple(want.shape):
            shape = tuple(got.shape) if isinstance(got, torch.Tensor) else type(got).__name__
            raise InputError(f"{path}: parameter {name!r} has shape {shape}, the network expects "
                             f"{tuple(want.shape)} (weights made for another architecture?)")
        if got.is_floating_point() and not torch.all(torch.isfinite(got)):
            raise InputError(f"{path}: parameter {name!r} contains NaN or Inf (corrupt or diverged training)")
    model.load_state_dict({k: v.to(own[k].dtype) for k, v in state.items()})
    return model


def _load_model(path: str | Path | None, default_name: str, kind: str, make) -> nn.Module:
    """The network ``make(payload config)`` with the weights of ``path`` (default: the package's
    ``default_name``), checked to be of ``kind``, in eval mode."""
    path = Path(path) if path else packaged_weights(default_name)
    payload = read_weights(path, kind)
    model = make(payload["config"])
    load_state(model, payload, path)
    return model.eval()


def load_sky_model(path: str | Path | None = None) -> SkyModel:
    """The sky model from a weights file (default: the package's), in eval mode."""
    return _load_model(path, SKY_WEIGHTS, "sky", lambda c: SkyModel(SkyNetConfig.from_dict(c)))


def load_light_model(path: str | Path | None = None) -> LightNet:
    """The image -> sky-vector predictor from a weights file (default: the package's), in eval mode."""
    return _load_model(path, LIGHT_WEIGHTS, "light", lambda c: LightNet(LightNetConfig.from_dict(c)))
