"""What limits the cross-frame model's temporal gain on a held-out temporal dataset (deep-OID, `ranad synth
--ref-frames all`)? Three measurements, printed as markdown tables (issue 7):

1. `weights`: how much of the temporal step's kernel falls on each frame of the window. The step is linear in its
   values, so feeding it the one-hot of each key's frame as values gives every centre bin's weight per frame
   (after the gate: (1 - g) on the centre plus g times the kernel).
2. `reweight`: the held-out FLIP and temporal error when the kernel's mass on frames +-1 and +-2 is scaled by s1
   and s2 at test time (renormalised; gate as learned or forced open). If more temporal averaging helped, scaling
   up would lower the temporal error. `sym` instead keeps only the symmetric part of each +-k pair's mass (the
   rest goes to the centre), which cancels a shading change that is linear in time.
3. `change`: how far a neighbour's bins are from the centre frame's after exact per-bin motion compensation, on
   the references (reference values moved with the noisy file's motion vectors; opaque bins whose object id is
   present in all five frames), against the single-frame model's own error on the same bins. This is the bias
   a neighbour brings: shading that really changes between frames (spinning objects, a moving camera).

    python runs/cpu-small-xf-t5/temporal_limits.py DATASET [--what weights,reweight,change]

A diagnostic, not part of the product: `reweight` re-implements CrossFrameRaNAD.reconstruct with the per-frame
scaling, and the sweep's settings are fixed below (not tuned on DATASET).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from ranad_core import metrics
from ranad_core.deep import DeepImage
from ranad_core.denoise import denoise_window
from ranad_core.evaluate import temporal_scenes
from ranad_core.exr import read_deep
from ranad_core.exr.sequence import Frame
from ranad_core.model.crossframe import temporal_layout
from ranad_core.model.store import load_model
from ranad_core.motion import FLOW_CHANNELS, compensate
from ranad_core.shot import window_of

SINGLE, CROSS, WINDOW, SPPS = "cpu-small-v1", "cpu-small-xf-v2", 5, (4, 16)
SWEEP = [dict(s1=1, s2=1), dict(s1=2, s2=3), dict(s1=3, s2=8), dict(s1=3, s2=8, gate=0.9), dict(sym=True)]


def frame_path(scene: Path, what: str, spp: int, f: int) -> str:
    return str(scene / "deepoid" / f"{what}_spp{spp}.{f:04d}.exr")


def frame_onehot(frames: list, gather: torch.Tensor) -> torch.Tensor:
    fid = torch.cat([torch.full((f.layout.pixels.shape[0],), i) for i, f in enumerate(frames)])[gather]
    return torch.nn.functional.one_hot(fid, len(frames)).float()


class Reweighted:
    """CrossFrameRaNAD.reconstruct with the temporal kernel's mass on frame offset +-k scaled by s_k (colour
    layers) and optionally the gate held at least at `gate`, or (`sym`) each +-k pair's mass cut to its smaller
    side, the rest moved to the centre; s = 1, no gate and no sym reproduce the model exactly."""

    def __init__(self, model, s1=1.0, s2=1.0, gate=None, sym=False, layers=("diffuse", "specular")):
        self.m, self.scale, self.gate, self.sym, self.layers = model, {0: 1.0, 1: s1, 2: s2}, gate, sym, layers
        self.weights = {name: [] for name in layers}   # per centre bin: its effective weight per frame

    def __call__(self, feats, frames, centre, values=None):
        m, c, out, n = self.m, frames[centre], {}, len(frames)
        keys, gather = temporal_layout([f.layout for f in frames]) if n > 1 else (None, None)
        for name, rec in m.single.recon.items():
            if name not in c.layers:
                continue
            vals = [f.layers[name] for f in frames]
            v = vals[centre]
            if n > 1:
                allv, allf = torch.cat(vals)[gather], torch.cat(feats)[gather]
                g = torch.sigmoid(m.temporal_gate[name](feats[centre]))
                if name in self.layers:
                    oh, ch = frame_onehot(frames, gather), allv.shape[1]
                    per_frame = torch.cat([(allv[:, :, None] * oh[:, None, :]).reshape(-1, ch * n), oh], 1)
                    y = m.temporal[name](feats[centre], allf, c.layout.pixels, keys, per_frame)
                    sums, mass = y[:, :ch * n].reshape(-1, ch, n), y[:, ch * n:]
                    if self.sym:
                        w = symmetric(mass, centre)
                    else:
                        s = torch.tensor([self.scale.get(abs(i - centre), 1.0) for i in range(n)])
                        w = mass * s / (mass * s).sum(-1, keepdim=True).clamp_min(1e-12)
                    t = (sums / mass.clamp_min(1e-12)[:, None, :] * w[:, None, :]).sum(-1)
                    if self.gate is not None:
                        g = g.clamp_min(self.gate)
                    if n == WINDOW:
                        eff = (1 - g) * torch.eye(n)[centre] + g * w
                        self.weights[name].append(eff.numpy())
                else:
                    t = m.temporal[name](feats[centre], allf, c.layout.pixels, keys, allv)
                v = v + g * (t - v)
            out[name] = rec(feats[centre], c.layout, v)
        return out


def symmetric(mass: torch.Tensor, centre: int) -> torch.Tensor:
    """Per-frame weights [N, F] with each +-k pair cut to min(w-k, w+k) and the excess on the centre."""
    w = mass.clone()
    for k in range(1, mass.shape[1]):
        a, b = centre - k, centre + k
        if a < 0 or b >= mass.shape[1]:
            continue
        low = torch.minimum(mass[:, a], mass[:, b])
        w[:, centre] += mass[:, a] + mass[:, b] - 2 * low
        w[:, a], w[:, b] = low, low
    return w


def run_shots(cross, data: dict) -> dict:
    """spp -> (FLIP, temporal error) means over the dataset's shots, every frame with its window."""
    res = {}
    for (_, spp), (seq, imgs, refs) in data.items():
        outs = []
        for f in range(len(seq)):
            members, c = window_of(seq[f], seq, WINDOW)
            outs.append(metrics.flat_rgb(denoise_window(cross, [imgs[x.frame] for x in members], c).image))
        res.setdefault(spp, []).append((np.mean([metrics.flip(r, o) for r, o in zip(refs, outs)]),
                                        metrics.temporal_error(outs, refs)))
    return {spp: np.mean(v, 0) for spp, v in res.items()}


def load_shots(dataset: Path) -> dict:
    data = {}
    for sc, m in temporal_scenes(str(dataset)):
        n = m["frames"]
        for spp in SPPS:
            seq = [Frame(frame_path(sc, "noisy", spp, f), f) for f in range(n)]
            data[sc.name, spp] = (seq, [read_deep(f.path) for f in seq],
                                  [metrics.flat_rgb(read_deep(frame_path(sc, "reference", spp, f))) for f in range(n)])
    return data


def weights_and_sweep(dataset: Path, what: set) -> None:
    cross = load_model(CROSS).model
    original = cross.reconstruct
    data = load_shots(dataset)
    print(f"### {CROSS} on {dataset.name}: the temporal step (window {WINDOW}, deep-OID)\n")
    # the sweep's first setting is the model as trained: one pass records the weights and scores that row
    sweep = SWEEP if "reweight" in what else SWEEP[:1]
    rows = []
    for cfg in sweep:
        rw = Reweighted(cross, **cfg)
        cross.reconstruct = rw
        rows.append((cfg, run_shots(cross, data)))
        if cfg is SWEEP[0] and "weights" in what:
            print("Mean weight per frame offset of the centre bins (full windows only; gate included):\n")
            print("| layer | -2 | -1 | 0 | +1 | +2 | effective frames (1 / sum w^2), median |\n"
                  "|---|---|---|---|---|---|---|")
            for name, w in rw.weights.items():
                w = np.concatenate(w)
                print(f"| {name} | " + " | ".join(f"{x:.3f}" for x in w.mean(0)) +
                      f" | {np.median(1 / (w ** 2).sum(1)):.2f} |")
            print()
    cross.reconstruct = original
    if "reweight" in what:
        single = {}
        for (_, spp), (seq, imgs, refs) in data.items():
            outs = [metrics.flat_rgb(denoise_window(load_single(), [im], 0).image) for im in imgs]
            single.setdefault(spp, []).append(metrics.temporal_error(outs, refs))
        print("Test-time scaling of the mass on frames +-1 (s1) and +-2 (s2) (sym: each pair cut to its symmetric "
              "part), colour layers; temporal error as a ratio to the single-frame model's:\n")
        print("| s1 | s2 | gate | spp | FLIP | temporal | / single-frame |\n|---|---|---|---|---|---|---|")
        for cfg, scores in rows:
            for spp, (fl, te) in scores.items():
                scaling = "sym | sym" if cfg.get("sym") else f"{cfg['s1']} | {cfg['s2']}"
                print(f"| {scaling} | {'>= %g' % cfg['gate'] if 'gate' in cfg else 'learned'} | "
                      f"{spp} | {fl:.4f} | {te:.6f} | {te / np.mean(single[spp]):.3f} |")
        print()


_single = None


def load_single():
    global _single
    if _single is None:
        _single = load_model(SINGLE).model
    return _single


def keyed(img: DeepImage) -> dict:
    """(pixel, object id) -> (tonemapped un-premultiplied colour, alpha)."""
    ch = img.channels
    a = img.values[:, ch.index("A")]
    rgb = img.values[:, [ch.index(c) for c in ("R", "G", "B")]] / np.maximum(a, 1e-4)[:, None]
    tm = metrics.tonemap(rgb)
    return {(int(p), int(i)): (c, al) for p, i, c, al in zip(img.pixel_index(), img.ids["id"], tm, a)}


def reference_change(dataset: Path) -> None:
    """Per opaque bin present in all five frames around each shot's centre: |neighbour - centre| of the
    compensated references, and the single-frame model's |denoised - reference| on the same bins."""
    acc = {}
    for sc, m in temporal_scenes(str(dataset)):
        centre = m["centre_frame"]
        for spp in SPPS:
            fr = range(centre - 2, centre + 3)
            noisy = [read_deep(frame_path(sc, "noisy", spp, f)) for f in fr]
            refs = [read_deep(frame_path(sc, "reference", spp, f)) for f in fr]
            flow = [n.values[:, [n.channels.index(c) for c in FLOW_CHANNELS]] for n in noisy]
            moving = [DeepImage(values=np.concatenate([r.values, f], 1), offsets=r.offsets, ids=r.ids,
                                channels=r.channels + list(FLOW_CHANNELS), data_window=r.data_window)
                      for f, r in zip(flow, refs)]
            moved, _ = compensate(moving, 2)
            k = [keyed(m) for m in moved]
            den = keyed(denoise_window(load_single(), [noisy[2]], 0).image)
            for key, (c, a) in k[2].items():
                if a < 0.99 or not all(key in x and x[key][1] > 0.99 for x in k):
                    continue
                t = [x[key][0] for x in k]
                acc.setdefault(f"single-frame model at {spp} spp: denoised - reference", []).append(
                    np.abs(den[key][0] - c).mean())
                if spp == SPPS[-1]:  # the references do not depend on the noisy spp's binning for deep-OID
                    for label, v in (("reference t-1", t[1]), ("reference t+1", t[3]),
                                     ("(reference t-1 + t+1) / 2", (t[1] + t[3]) / 2),
                                     ("reference t-2", t[0]), ("reference t+2", t[4]),
                                     ("mean of the five references", sum(t) / 5)):
                        acc.setdefault(label + " - reference t", []).append(np.abs(v - c).mean())
    print(f"### {dataset.name}: compensated neighbours against the centre frame (tonemapped colour, mean abs, "
          f"opaque bins present in all five frames)\n")
    print("| quantity | mean abs | bins |\n|---|---|---|")
    for label, v in acc.items():
        print(f"| {label} | {np.mean(v):.4f} | {len(v)} |")
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--what", default="weights,reweight,change")
    args = ap.parse_args()
    what = set(args.what.split(","))
    torch.set_grad_enabled(False)
    if what & {"weights", "reweight"}:
        weights_and_sweep(args.dataset, what)
    if "change" in what:
        reference_change(args.dataset)


if __name__ == "__main__":
    main()
