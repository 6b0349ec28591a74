"""`ranad eval` with OIDN's prefiltered auxiliary images (OIDN's documented highest-quality mode: the albedo and
normal denoised by their own OIDN filters, then the beauty filtered with cleanAux) in place of the raw ones, in
ranad's flat prior (`--where prior`), in the flat OIDN baseline (`--where baseline`) or both.

At 4 spp a box-filtered render's flattened albedo and normal are themselves noisy (texture, edges, glass), and
OIDN takes their noise for detail. The study asks whether the cleaner aux makes OIDN's prior (which ranad's kernels
follow at 3-8 px) and the comparator better, and by how much on the held-out sets. (The evaluations ran with this
script's own copies of the OIDN calls, since replaced by `baselines.prefiltered` and `baselines.oidn_run`, which
make the same calls in the same order; `ranad eval` scores the same baseline itself as `oidn-clean`.)

With `--remod`, ranad's demodulated diffuse layer is multiplied back by a cleaner albedo than the one it was divided
by: each bin's albedo times its pixel's gain from the flattened albedo to OIDN's prefiltered one (the division keeps
the bin's own albedo, so the kernels still average irradiance). At low spp a bin's albedo is the mean of a few
samples of the texture under the pixel; the reference's is the mean of many, and the remodulation carries the
difference into the output.

Usage (from the data folder): python clean_aux.py --where prior|baseline|both|none [--remod] SET -o OUT [ranad eval
       options]; with `--command train`, `ranad train` under the same patches (training computes the prior through
       prior._oidn too)
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import pyoidn  # noqa: E402

from ranad_core import baselines  # noqa: E402
from ranad_core.model import prior  # noqa: E402


def clean_oidn(colour: np.ndarray, albedo=None, normal=None) -> np.ndarray:
    """OIDN (HDR) with prefiltered albedo and normal and cleanAux; without aux, plain OIDN."""
    colour = np.ascontiguousarray(colour, np.float32)
    if albedo is None:
        return np.asarray(pyoidn.denoise(colour, hdr=True), np.float32)
    aux = {"albedo": baselines.prefiltered(pyoidn, "albedo", albedo)}
    if normal is not None:
        aux["normal"] = baselines.prefiltered(pyoidn, "normal", normal)
    return baselines.oidn_run(pyoidn, {"color": colour, **aux}, "with prefiltered guides", hdr=True, cleanAux=True)


class _CleanPyoidn:
    """pyoidn as baselines.oidn_flat calls it (pyoidn.denoise(colour, hdr=True, albedo=, normal=))."""

    def __getattr__(self, name):
        return getattr(pyoidn, name)

    @staticmethod
    def denoise(colour, hdr=True, albedo=None, normal=None, **kw):
        return clean_oidn(colour, albedo, normal)


_CLEAN = {}


def remodulate_with_clean_albedo() -> None:
    """Patches inputs.prepare to record each prepared image's clean per-bin modulation and ranad's demodulated to
    multiply back by it (see the module's docstring)."""
    import torch

    from ranad_core.baselines import composite_groups
    from ranad_core.channels import ALBEDO
    from ranad_core.model import inputs, ranad, reconstruction

    orig_prepare = inputs.prepare

    def prepare(img, *a, **k):
        out = orig_prepare(img, *a, **k)
        if out.modulation is not None and img.num_bins:
            alb = np.clip(np.nan_to_num(img.columns(list(ALBEDO))), 0, 1).astype(np.float32)
            (flat,) = composite_groups(img, [(alb, False)])
            h, w = img.height, img.width
            clean = baselines.prefiltered(pyoidn, "albedo", np.clip(flat, 0, 1).reshape(h, w, 3)).reshape(-1, 3)
            gain = np.clip((np.clip(clean, 0, 1) + inputs.DEMOD_FLOOR) / (flat + inputs.DEMOD_FLOOR), 0.5, 2.0)
            counts = np.diff(img.offsets)
            per_bin = np.repeat(gain, counts, axis=0)
            _CLEAN[out.modulation.data_ptr()] = (out.modulation * torch.from_numpy(per_bin.astype(np.float32)))
        return out

    def demodulated(rec, feat, layout, values, modulation, guide=None):
        if modulation is None:
            return rec(feat, layout, values, guide)
        m = reconstruction.per_channel(modulation, values)
        clean = _CLEAN.get(modulation.data_ptr())
        m_out = m if clean is None else reconstruction.per_channel(clean, values)
        return m_out * rec(feat, layout, values / m, guide)

    inputs.prepare = prepare
    import ranad_core.denoise as den
    if getattr(den, "prepare", None) is orig_prepare:
        den.prepare = prepare
    ranad.demodulated = demodulated


def main() -> None:
    args = sys.argv[1:]
    command = "eval"
    if "--command" in args:  # another ranad command (train) under the same patches
        i = args.index("--command")
        command = args[i + 1]
        del args[i:i + 2]
    i = args.index("--where")
    where = args[i + 1]
    del args[i:i + 2]
    if "--remod" in args:
        args.remove("--remod")
        remodulate_with_clean_albedo()
    if where in ("prior", "both"):
        prior._oidn = lambda colour, albedo, normal: clean_oidn(colour, albedo, normal)
    if where in ("baseline", "both"):
        import builtins
        real_import = builtins.__import__

        def patched(name, *a, **k):  # baselines.oidn_flat imports pyoidn inside the function
            if name == "pyoidn":
                return _CleanPyoidn()
            return real_import(name, *a, **k)
        orig = baselines.oidn_flat

        def oidn_flat(noisy, **kw):
            builtins.__import__ = patched
            try:
                return orig(noisy, **kw)
            finally:
                builtins.__import__ = real_import
        baselines.oidn_flat = oidn_flat
        from ranad_core import evaluate
        evaluate.oidn_flat = oidn_flat
    from ranad_cli.main import main as ranad_main
    sys.argv = ["ranad", command, *args]
    ranad_main()


if __name__ == "__main__":
    main()
