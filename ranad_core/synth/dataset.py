"""A training/test dataset on disk: scenes of noisy frames and centre-frame references, one folder per scene.

Layout of DATASET/scene_NNNN/ (NNNN = scene index):
    {kind}/noisy_spp{S}.{FFFF}.exr        every frame F at each noisy spp S (kind: deepz, deepoid)
    {kind}/reference_spp{S}.{CCCC}.exr    the centre frame C's reference binned into noisy_spp{S}'s bins
    manifest.json                         the scene's recipe, files, statistics; written last, so a folder with
                                          a manifest is complete (a rerun skips it: resumable)
Everything derives from (seed, scene index): the same command writes identical files.
"""

from __future__ import annotations

import json
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..errors import RanadError
from ..exr import write_deep
from ..fileutil import atomic_output
from .binning import Z_GAP_REL
from .enclosure import enclose
from .scene import PRESETS, make_scene
from .trace import load_frame

KINDS = {"deepz": "z", "deepoid": "oid"}


@dataclass
class SynthConfig:
    out: str
    scenes: int = 8
    size: int = 128
    frames: int = 3
    spp: tuple = (4, 16, 64)
    ref_spp: int = 1024
    seed: int = 0
    presets: tuple = PRESETS
    kinds: tuple = ("deepz", "deepoid")
    ref_frames: str = "centre"        # "centre", or "all" (references for every frame: temporal evaluation)
    motion: float = 1.0               # per-frame motion scale (scene.make_scene): 0.5 = twice the frame rate
    bin_gap: float = Z_GAP_REL        # deep-Z split rule's relative depth gap (binning.layout_from_samples)
    sampler: str = "independent"      # noisy frames' samples: "independent", "stratified" or "sobol" (trace)
    guides: str = "first-hit"         # albedo/normal of the first surface, or "through-specular" (trace)
    pixel_filter: str = "box"         # "box" (a sample in its own pixel) or "gaussian" (pixel_filter.py)
    filter_width: tuple = (2.0, 2.0)  # the Gaussian's width in pixels, or the range each scene draws it from
    enclosure: float = 0.0            # share of scenes put inside a room (enclosure.py: walls, bounce light)


def scene_seed(seed: int, index: int) -> int:
    return int(np.random.SeedSequence([seed, index]).generate_state(1)[0])


def scene_preset(cfg: SynthConfig, index: int) -> str:
    """The scene's preset or family: cfg.presets in turn."""
    return cfg.presets[index % len(cfg.presets)]


def scene_dir(cfg: SynthConfig, index: int) -> str:
    return os.path.join(cfg.out, f"scene_{index:04d}")


def is_done(cfg: SynthConfig, index: int) -> bool:
    return os.path.isfile(os.path.join(scene_dir(cfg, index), "manifest.json"))


def _worker_init(threads: int) -> None:
    """Each worker process gets its share of the cores for Dr.Jit (both using all cores oversubscribes them), and
    ends with the parent (a killed `ranad synth` left its workers rendering; see ranad_core/procutil.py)."""
    from ..procutil import die_with_parent
    from .mitsuba_env import mitsuba

    die_with_parent()

    mitsuba()
    import drjit as dr
    import torch

    dr.set_thread_count(threads)
    torch.set_num_threads(threads)


def filter_width(cfg: SynthConfig, sseed: int) -> float:
    """The scene's filter width: fixed, or drawn from cfg.filter_width's range by a stream of its own (the scene's
    other draws stay as they were)."""
    lo, hi = cfg.filter_width
    return lo if hi <= lo else round(float(np.random.default_rng([sseed, 0xF11]).uniform(lo, hi)), 3)


def make_one(cfg: SynthConfig, index: int) -> dict:
    """Renders and writes one scene; returns its manifest."""
    from .render import bin_noisy, noisy_samples, render_reference

    t0 = time.perf_counter()
    sseed = scene_seed(cfg.seed, index)
    preset = scene_preset(cfg, index)
    spec = make_scene(sseed, preset, cfg.size, cfg.frames, cfg.motion)
    enclosed = enclose(spec, cfg.enclosure)
    centre = cfg.frames // 2
    root = scene_dir(cfg, index)
    files, stats = [], {}
    film = (cfg.pixel_filter, filter_width(cfg, sseed))
    bins_per_px = {k: [] for k in cfg.kinds}
    ref_frames = list(range(cfg.frames)) if cfg.ref_frames == "all" else [centre]
    for kind_name in cfg.kinds:
        os.makedirs(os.path.join(root, kind_name), exist_ok=True)
        stats[kind_name] = {"reference_unbinned_energy": {}}
    for frame in range(cfg.frames):
        fs = load_frame(spec, frame)
        layouts = []  # (kind, spp, layout): the frame's reference is traced once and binned into each
        for spp in cfg.spp:
            samples = noisy_samples(spec, frame, spp, sseed + 7919 * frame + spp, fs, cfg.sampler,
                                    cfg.guides == "through-specular", film)
            for kind_name in cfg.kinds:
                img, lay = bin_noisy(spec, samples, spp, KINDS[kind_name], cfg.bin_gap)
                path = os.path.join(root, kind_name, f"noisy_spp{spp}.{frame:04d}.exr")
                write_deep(path, img)
                files.append(os.path.relpath(path, root))
                counts = np.diff(lay.offsets)
                bins_per_px[kind_name].append(float(counts[counts > 0].mean()) if (counts > 0).any() else 0.0)
                if frame in ref_frames:
                    layouts.append((kind_name, spp, lay))
        if frame not in ref_frames:
            continue
        # the centre frame's seed is the one datasets made before references of every frame existed
        refs = render_reference(spec, frame, cfg.ref_spp, [lay for _, _, lay in layouts],
                                sseed + 104729 + 15485863 * (frame - centre), fs, film)
        for (kind_name, spp, _), (img, lost) in zip(layouts, refs):
            path = os.path.join(root, kind_name, f"reference_spp{spp}.{frame:04d}.exr")
            write_deep(path, img)
            files.append(os.path.relpath(path, root))
            key = str(spp) if frame == centre else f"{spp}@{frame}"
            stats[kind_name]["reference_unbinned_energy"][key] = lost
    for kind_name in cfg.kinds:
        stats[kind_name]["bins_per_covered_pixel"] = float(np.mean(bins_per_px[kind_name]))
    manifest = {"scene": index, "seed": sseed, "preset": preset, "size": cfg.size, "frames": cfg.frames,
                "motion": cfg.motion, "centre_frame": centre, "reference_frames": ref_frames, "spp": list(cfg.spp),
                "ref_spp": cfg.ref_spp, **({"bin_gap": cfg.bin_gap} if cfg.bin_gap != Z_GAP_REL else {}),
                **({"sampler": cfg.sampler} if cfg.sampler != "independent" else {}),
                **({"guides": cfg.guides} if cfg.guides != "first-hit" else {}),
                **({"pixel_filter": list(film)} if cfg.pixel_filter != "box" else {}),
                **({"enclosure": cfg.enclosure, "enclosed": enclosed} if cfg.enclosure else {}),
                "light_groups": spec.light_groups, "objects": len(spec.objects), "files": files, "stats": stats,
                "seconds": round(time.perf_counter() - t0, 2)}
    with atomic_output(os.path.join(root, "manifest.json")) as tmp:
        with open(tmp, "w") as f:
            json.dump(manifest, f, indent=1)
    return manifest


# a manifest leaves these out where they have their default (make_one): compared as SynthConfig's default when absent
_ABSENT = {k: SynthConfig.__dataclass_fields__[k].default
           for k in ("bin_gap", "sampler", "guides", "pixel_filter", "enclosure")}


def _recipe(cfg: SynthConfig, index: int) -> dict:
    """What a complete scene's manifest must agree on with the command that resumes its folder."""
    return {"seed": scene_seed(cfg.seed, index), "preset": scene_preset(cfg, index), "size": cfg.size,
            "frames": cfg.frames, "spp": list(cfg.spp), "ref_spp": cfg.ref_spp, "motion": cfg.motion,
            "bin_gap": cfg.bin_gap, "sampler": cfg.sampler, "guides": cfg.guides, "pixel_filter": cfg.pixel_filter,
            "enclosure": cfg.enclosure}


def check_resumable(cfg: SynthConfig, index: int) -> None:
    """A complete scene is skipped on a rerun, so it must be the scene this command would make: a folder made with
    other options (another sampler, --enclosure, spp ...) would otherwise end up a silent mix of two recipes."""
    path = os.path.join(scene_dir(cfg, index), "manifest.json")
    try:
        with open(path) as f:
            manifest = json.load(f)
    except (OSError, ValueError) as e:
        raise RanadError(f"unreadable scene manifest ({e}); remove the scene's folder to render it again", path) \
            from None
    for key, want in _recipe(cfg, index).items():
        if key not in manifest and key not in _ABSENT:
            continue   # written by a version that did not record it
        have = manifest.get(key, _ABSENT.get(key))
        if key == "pixel_filter" and isinstance(have, list):   # [filter, the scene's width]
            have = have[0]
        if have != want:
            raise RanadError(f"this scene was made with {key} {have!r}, and this command asks for {want!r}: write "
                             f"into another folder, or resume with the options it was made with", scene_dir(cfg, index))


def run(cfg: SynthConfig, workers: int = 1, progress=None) -> list:
    """Renders every scene not already complete (after checking the complete ones were made by the same recipe);
    returns the manifests written."""
    todo = []
    for i in range(cfg.scenes):
        if is_done(cfg, i):
            check_resumable(cfg, i)
        else:
            todo.append(i)
    os.makedirs(cfg.out, exist_ok=True)
    done = []
    if workers <= 1:
        for i in todo:
            done.append(make_one(cfg, i))
            if progress:
                progress(1)
        return done
    import multiprocessing as mp

    threads = max(1, (os.cpu_count() or 1) // workers)
    with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn"), initializer=_worker_init,
                             initargs=(threads,)) as pool:
        for m in pool.map(make_one, [cfg] * len(todo), todo):
            done.append(m)
            if progress:
                progress(1)
    return done
