"""A picture of one scene's edit error (what README.md's tables average), written at twice the size as
`glass_SET_SCENE_SPP.png` in the current folder. Top row: the edit of the reference, of the model, of the model
with the noisy alpha (x/(1+x) tone-mapped), then the FLIP maps of the last two (white = 0.3). Bottom row: the
reference's flattened alpha; the model's and the noisy input's flattened alpha minus it (red above, blue below,
full at 0.1); where the model's FLIP exceeds the noisy alpha's, and the other way round (white = 0.2).

Usage (from the folder that holds the sets): python runs/glass-edit-s14/error_maps.py SET SPP SCENE [MODEL]"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "edit-oracles-s12"))
sys.path.insert(0, os.path.dirname(__file__))
from common import scenes, set_alpha  # noqa: E402
from where_oracle import flip_map  # noqa: E402
from ranad_core.channels import ALPHA  # noqa: E402
from ranad_core.metrics import composite_edit, split_depth  # noqa: E402
from ranad_core.model.store import load_model  # noqa: E402


def tonemapped(x):
    x = np.maximum(x, 0)
    return (np.clip((x / (1 + x)) ** (1 / 2.2), 0, 1) * 255).astype(np.uint8)


def grey(x, full):
    return np.repeat((np.clip(x / full, 0, 1) * 255).astype(np.uint8)[..., None], 3, 2)


def signed(x, full):
    out = np.zeros(x.shape + (3,), np.uint8)
    out[..., 0] = np.clip(x / full, 0, 1) * 255
    out[..., 2] = np.clip(-x / full, 0, 1) * 255
    return out


def flat_alpha(img):
    return img.flatten()[..., img.channels.index(ALPHA)]


def main(dataset, spp, scene, model_name=None):
    import OpenImageIO as oiio

    model = load_model(model_name).model
    for name, noisy, ref, out, _, _ in scenes(dataset, model, spp, "deepz"):
        if name != scene:
            continue
        z = split_depth(ref)
        target = composite_edit(ref, z)
        edit_model, edit_noisy = composite_edit(out, z), composite_edit(set_alpha(out, noisy.channel(ALPHA)), z)
        f_model, f_noisy = flip_map(target, edit_model), flip_map(target, edit_noisy)
        a_ref, a_model, a_noisy = flat_alpha(ref), flat_alpha(out), flat_alpha(noisy)
        print(f"{name}: edit FLIP {f_model.mean():.4f} (noisy alpha {f_noisy.mean():.4f}); flattened alpha MAE "
              f"{np.abs(a_model - a_ref).mean():.4f} (noisy {np.abs(a_noisy - a_ref).mean():.4f})")
        top = [tonemapped(target), tonemapped(edit_model), tonemapped(edit_noisy), grey(f_model, 0.3),
               grey(f_noisy, 0.3)]
        bottom = [grey(a_ref, 1), signed(a_model - a_ref, 0.1), signed(a_noisy - a_ref, 0.1),
                  grey(np.maximum(f_model - f_noisy, 0), 0.2), grey(np.maximum(f_noisy - f_model, 0), 0.2)]
        im = np.concatenate([np.concatenate(top, 1), np.concatenate(bottom, 1)], 0)
        im = np.ascontiguousarray(np.repeat(np.repeat(im, 2, 0), 2, 1))
        path = f"glass_{dataset}_{name}_{spp}.png"
        png = oiio.ImageOutput.create("png")
        png.open(path, oiio.ImageSpec(im.shape[1], im.shape[0], 3, "uint8"))
        png.write_image(im)
        png.close()
        print("wrote", path)


if __name__ == "__main__":
    main(*sys.argv[1:])
