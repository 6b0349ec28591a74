"""`ranad eval` with the flat prior's OIDN run without the albedo/normal guides (a diagnostic, session 24): on glass
the guides are the pane's (ranad synth writes the first surface's albedo and normal), so guided OIDN smooths what
is seen through it, and the prior carries that into the model. Usage: python ev_noguide.py EVAL ARGS..."""
import sys

import ranad_core.model.prior as prior

real = prior.flat_images
prior.flat_images = lambda srt, rgb, guides: real(srt, rgb, False)

from ranad_cli.main import cli  # noqa: E402

cli.main(["eval", *sys.argv[1:]])
