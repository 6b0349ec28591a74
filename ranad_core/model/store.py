"""Loading and saving model weights: shipped models by name, safetensors files, training checkpoints.

A shipped model is `ranad_core/weights/<name>.safetensors` with a model card `<name>.md` beside it. The
safetensors metadata holds the architecture (`model_config`, JSON) and provenance (training step, data recipe),
so a file always loads into the architecture it was trained with. A model's id is its name plus the first 12 hex
digits of a SHA-256 of its content (`content_digest`: the metadata and the tensors, in a canonical order): caches
and eval tables record it, so results name the exact weights. Not of the file's bytes: safetensors writes the
metadata keys in a different order in each process, so exporting one checkpoint twice gave two ids.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import torch

from ..errors import RanadError
from ..fileutil import atomic_output
from .config import ModelConfig
from .inputs import feature_dim
from .ranad import RaNAD

WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights"
DEFAULT_MODEL = "cpu-small-pdl-gza-v9"       # single frames
DEFAULT_CROSS_MODEL = "cpu-small-pdl-gza-xg-v9"  # sequences: frames with neighbours


def default_model(sequence: bool) -> str:
    """The shipped model `ranad denoise` uses without --model: the cross-frame one for sequences (when shipped)."""
    if sequence and (WEIGHTS_DIR / f"{DEFAULT_CROSS_MODEL}.safetensors").is_file():
        return DEFAULT_CROSS_MODEL
    return DEFAULT_MODEL


def default_model_for(frame_numbers, window: int | None) -> str:
    """default_model for a shot: a sequence is frames with at least one consecutive pair of numbers, unless the
    user asked for windows of one frame (--window 1)."""
    numbers = {n for n in frame_numbers if n is not None}
    return default_model(any(n + 1 in numbers for n in numbers) and window != 1)


@dataclass
class LoadedModel:
    model: RaNAD                  # or CrossFrameRaNAD (config.window > 1)
    model_id: str
    metadata: dict


def training_window(loaded: LoadedModel, fallback: int = 3) -> int:
    """Frames per window a cross-frame model was trained with (its `train_config`): the window `ranad denoise`
    and `ranad eval --temporal` use unless told otherwise, since the frame ids of wider offsets were never
    trained. `fallback` for files without that record."""
    try:
        window = int(json.loads(loaded.metadata.get("train_config") or "{}").get("window", fallback))
    except (ValueError, TypeError, AttributeError):
        return fallback
    return max(1, min(window, loaded.model.config.window))


def shipped_models() -> list[str]:
    return sorted(p.stem for p in WEIGHTS_DIR.glob("*.safetensors"))


def content_digest(state: dict, metadata: dict) -> str:
    """First 12 hex digits of the SHA-256 of the metadata (keys sorted) and every tensor (names sorted: name,
    dtype, shape, bytes): equal for equal weights and provenance, whatever the file's byte layout, so a checkpoint
    and its export without extra notes share it."""
    h = hashlib.sha256(json.dumps(metadata, sort_keys=True).encode())
    for name in sorted(state):
        t = state[name].detach().cpu().contiguous()
        h.update(f"\0{name}\0{t.dtype}\0{tuple(t.shape)}\0".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes())
    return h.hexdigest()[:12]


def resolve(spec: str | None) -> Path:
    """A model name (shipped), a .safetensors file or a training checkpoint (.pt) -> its path."""
    spec = spec or DEFAULT_MODEL
    path = Path(spec)
    if path.is_dir() and (path / "checkpoint.pt").is_file():
        return path / "checkpoint.pt"
    if path.is_file():
        return path
    shipped = WEIGHTS_DIR / f"{spec}.safetensors"
    if shipped.is_file():
        return shipped
    known = ", ".join(shipped_models()) or "none shipped"
    raise RanadError(f"no such model (shipped: {known}; or give a .safetensors file or a training run)", spec)


def load_model(spec: str | None = None, backend: str = "auto") -> LoadedModel:
    """The model in eval mode, with its id and metadata."""
    path = resolve(spec)
    state, meta = read_weights(path)
    try:
        config = ModelConfig.from_dict(json.loads(meta["model_config"]))
    except Exception as e:  # foreign metadata: one line naming the file
        raise RanadError(f"not a ranad model ({type(e).__name__}: {e})", path) from None
    if config.window > 1:
        from .crossframe import CrossFrameRaNAD

        model = CrossFrameRaNAD(config, feature_dim(config.features), backend=backend)
    else:
        model = RaNAD(config, feature_dim(config.features), backend=backend)
    try:
        model.load_state_dict(state)
    except RuntimeError as e:
        raise RanadError(f"weights do not fit config {config.name!r}: {str(e).splitlines()[0]}", path) from None
    model.eval()
    if str(meta.get("halo", "")).isdigit():   # measured by `ranad export --measure-halo` (halo.py)
        model.measured_halo = int(meta["halo"])
    return LoadedModel(model, f"{model_name(path)}@{content_digest(state, meta)}", meta)


def model_name(path: Path) -> str:
    """The name a model's id carries: a .safetensors file's stem, or a training run's folder name."""
    return path.stem if path.suffix == ".safetensors" else path.parent.name


def read_weights(path: Path) -> tuple[dict, dict]:
    """(tensors, metadata) of a .safetensors model or a training checkpoint (its metadata as an export would
    write it); a RanadError naming the file when it is neither."""
    if path.suffix != ".safetensors":
        ckpt = load_checkpoint(path)
        return ckpt["model"], checkpoint_metadata(ckpt)
    from safetensors import safe_open
    from safetensors.torch import load_file

    try:
        with safe_open(str(path), framework="pt") as f:
            meta = dict(f.metadata() or {})
        return load_file(str(path)), meta
    except Exception as e:  # noqa: BLE001 - corrupt or foreign files: one line naming the file
        raise RanadError(f"not a ranad model ({type(e).__name__}: {e})", path) from None


CHECKPOINT_KEYS = ("model", "model_config", "step")


def load_checkpoint(path, keys=CHECKPOINT_KEYS) -> dict:
    """A training checkpoint (torch.load with weights_only=True: a crafted file runs no code), or a RanadError
    naming the file when it is not one (truncated, foreign, or without the entries ranad writes)."""
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - unpickling errors, zip errors, truncation: all one message
        raise RanadError(f"not a ranad training checkpoint ({type(e).__name__}: {str(e).splitlines()[0][:200]})",
                         str(path)) from None
    missing = [k for k in keys if not isinstance(ckpt, dict) or k not in ckpt]
    if missing:
        raise RanadError(f"not a ranad training checkpoint (no {', '.join(missing)})", str(path))
    return ckpt


def checkpoint_metadata(ckpt: dict) -> dict:
    """The metadata a training checkpoint carries into its exported file (architecture, step, training settings),
    the same whether the checkpoint is exported or loaded directly."""
    return {"model_config": json.dumps(ckpt["model_config"]), "step": str(ckpt.get("step")),
            "train_config": json.dumps(ckpt.get("train_config", {}))}


def interpolate_weights(state: dict, meta: dict, other: str, t: float) -> tuple[dict, dict]:
    """(1 - t) x `state` + t x the weights of model `other` (a name, file or run), tensor by tensor, with the
    metadata saying so. Why: weights between a model and its own fine-tuned descendant often hold up better on data
    neither was trained on than either end (robust fine-tuning's weight interpolation); both must be the same
    architecture, and tensors that are not floating point (counters, indices) must already agree."""
    if not 0.0 <= t <= 1.0:
        raise RanadError(f"interpolation weight {t} outside [0, 1]", other)
    path = resolve(other)
    other_state, other_meta = read_weights(path)
    if json.loads(other_meta.get("model_config", "null")) != json.loads(meta.get("model_config", "null")):
        raise RanadError("cannot interpolate: another model configuration", path)
    if set(other_state) != set(state) or any(other_state[k].shape != v.shape for k, v in state.items()):
        raise RanadError("cannot interpolate: the tensors differ in names or shapes", path)
    out = {}
    for k, v in state.items():
        if v.is_floating_point():
            out[k] = ((1.0 - t) * v.double() + t * other_state[k].double()).to(v.dtype)
        elif torch.equal(v, other_state[k]):
            out[k] = v
        else:
            raise RanadError(f"cannot interpolate: integer tensor {k!r} differs", path)
    meta = {k: v for k, v in meta.items() if k not in ("halo", "halo_measured_on")}   # the ends' halos, not its own
    meta["interpolated"] = f"{t:g} x {model_name(path)}@{content_digest(other_state, other_meta)}"
    return out, meta


def export_weights(checkpoint: str | Path, out: str | Path, extra: dict | None = None,
                   interpolate: tuple[str, float] | None = None) -> Path:
    """Write a training checkpoint's model weights as safetensors with the config and provenance metadata; a
    .safetensors source is copied with its metadata updated by `extra`. `interpolate` (MODEL, t): the weights
    written are (1 - t) x the checkpoint's + t x MODEL's (interpolate_weights)."""
    from safetensors.torch import save_file

    state, meta = read_weights(resolve(str(checkpoint)))
    if interpolate is not None:
        state, meta = interpolate_weights(state, meta, *interpolate)
    state = {k: v.contiguous() for k, v in state.items()}
    meta.update({k: str(v) for k, v in (extra or {}).items()})
    with atomic_output(out) as tmp:
        save_file(state, tmp, metadata=meta)
    return Path(out)
