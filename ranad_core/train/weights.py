"""The loss terms and their default weights (losses.py computes them), in a module without torch so that the
command line can list them in `ranad train --help` without importing it."""

WEIGHTS = {"diffuse": 1.0, "specular": 1.0, "composite": 1.0, "composite_ssim": 0.5, "alpha": 0.5, "depth": 0.2,
           "separation": 0.0, "separation_ssim": 0.0, "edit": 0.0, "edit_ssim": 0.0, "composite_grad": 0.0,
           "composite_coarse": 0.0, "flip": 0.0, "edit_flip": 0.0}
