"""``ranad eval``: score a model and the baselines on a held-out `ranad synth` dataset."""

from __future__ import annotations

import math
import os

import click
from tqdm import tqdm

from ranad_core.errors import RanadError

from .params import FiniteFloat, int_list


@click.command("eval")
@click.argument("dataset", type=click.Path(file_okay=False))
@click.option("-o", "--out", "out", required=True, type=click.Path(file_okay=False),
              help="Folder for eval.md (summary table), eval.csv (every row) and grid.png (created).")
@click.option("--model", default=None, help="Shipped model name, .safetensors file or training run folder "
                                            "(default: the shipped default model).")
@click.option("--spp", default=None, help="Only these noisy sample counts, comma-separated (default: all).")
@click.option("--kind", "kinds", multiple=True, type=click.Choice(["deepz", "deepoid"]),
              help="Only these deep kinds (default: both).")
@click.option("--scenes", default=None, type=click.IntRange(1), help="Only the first N scenes.")
@click.option("--grid", "grid_pairs", default=4, show_default=True, type=click.IntRange(0),
              help="Rows of the comparison grid (the first pairs evaluated).")
@click.option("--temporal", is_flag=True,
              help="Temporal evaluation instead (datasets made with `ranad synth --ref-frames all`): FLIP and "
                   "temporal error of noisy, OIDN, the single-frame --model and the cross-frame --cross-model.")
@click.option("--cross-model", default=None, help="Cross-frame model for --temporal (name, file or run).")
@click.option("--window", default=None, type=click.IntRange(2, 7),
              help="Frames per window of the cross-frame model in --temporal (default: the window it was trained "
                   "with).")
@click.option("--held-out", "held_out", default="",
              help="Scene families (synth presets) the model never trained on, comma-separated: their scenes are "
                   "reported apart from in-family ones (the numbers to steer by).")
@click.option("--exposure", "exposures", default="0", show_default=True,
              help="Exposure sweep: stops by which every input is scaled (comma-separated, e.g. -6,0,6); outputs "
                   "are scaled back before scoring, so rows at different exposures compare directly.")
@click.option("--bin-merge", "bin_merge", type=FiniteFloat(0, 0.5), default=None,
              help="ranad's thin-bin merging gap, as `ranad denoise --bin-merge` (default: its default; 0: off).")
@click.option("--dark-radius", "dark_radius", type=click.IntRange(0, 8), default=None,
              help="ranad's black neighbourhoods, as `ranad denoise --dark-radius` (default: its default; 0: off).")
@click.option("--light-match/--no-light-match", "light_match", default=True, show_default=True,
              help="ranad's light matching to the noisy render's local light, as `ranad denoise --light-match`.")
def eval_cmd(dataset, out, model, spp, kinds, scenes, grid_pairs, temporal, cross_model, window, held_out,
             exposures, bin_merge, dark_radius, light_match):
    """Evaluate on DATASET (the output of `ranad synth` with other seeds than the training data): for every
    scene, deep kind and spp, the noisy input, flat OIDN, OIDN then recolour (the studio workflow) and ranad
    are scored against the reference: SMAPE, DSSIM and HDR-FLIP of the flattened beauty; per-bin SMAPE; a
    compositing edit (a layer inserted at the median depth, the foreground recoloured) and a depth separation
    (front and back flattened alone), each compared with the same edit on the reference. Lower is better.
    Frames with albedo also score OIDN with its guides prefiltered (oidn-clean, OIDN's highest-quality mode) and
    the recolour from it (recolour-clean); the ratio tables give ranad against both.
    """
    from ranad_core import evaluate as ev
    from ranad_core.exr.flat import write_flat
    from ranad_core.model.store import load_model

    spps = int_list(spp) if spp else None
    loaded = load_model(model)
    if temporal:
        return _temporal(dataset, out, loaded, cross_model, spps, kinds, scenes, window)
    try:
        stops = tuple(float(x) for x in exposures.split(",") if x.strip())
    except ValueError:
        raise click.BadParameter(f"not a list of numbers: {exposures!r}", param_hint="--exposure") from None
    if not stops or not all(math.isfinite(x) and abs(x) <= 64 for x in stops):
        raise click.BadParameter(f"expected stops within -64..64, got {exposures!r}", param_hint="--exposure")
    held = tuple(x.strip() for x in held_out.split(",") if x.strip())
    from ranad_core.train.data import find_pairs

    missing = []
    find_pairs(dataset, missing)
    missing = [p for p in missing if (not spps or p.spp in spps) and (not kinds or p.kind in kinds)]
    total = ev.count_pairs(dataset, spps, kinds, scenes) * len(stops)
    if total == 0:
        raise RanadError("no pairs match the --spp/--kind selection" + (f" ({len(missing)} noisy file(s) have no "
                         f"reference, e.g. {missing[0].reference})" if missing else ""), dataset)
    if missing:   # a scene still rendering, or a reference lost: the scores leave them out, and say so
        click.echo(f"ranad: warning: {len(missing)} noisy file(s) without their reference are not scored, e.g. "
                   f"{missing[0].reference}", err=True)
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as e:
        raise RanadError(f"cannot create the output folder ({e.strerror or e})", out) from None
    with tqdm(total=total, desc="eval", unit="pair") as bar:
        result = ev.evaluate(dataset, loaded.model, spps, kinds, scenes, grid_pairs, bar.update, stops, held,
                             bin_merge, dark_radius, light_match)
    name = os.path.basename(os.path.normpath(dataset))
    n_scenes = len({r["scene"] for r in result.rows})
    if held or stops != (0,):
        table = ev.grouped_markdown(result.rows, f"{loaded.model_id} on {name}, {n_scenes} scenes"
                                                 + (f", held-out families {', '.join(held)}" if held else ""))
    else:
        table = ev.markdown(result.rows, f"{loaded.model_id} on {name}, {n_scenes} scenes")
    from ranad_core.fileutil import atomic_output

    with atomic_output(os.path.join(out, "eval.md")) as tmp:
        with open(tmp, "w") as f:
            f.write(table + "\nColumns of the grid: " + ", ".join(result.grid_columns) + "\n")
    ev.write_csv(result.rows, os.path.join(out, "eval.csv"))
    if result.grid:
        img = ev.grid_image(result)
        write_flat(os.path.join(out, "grid.png"), img, ["R", "G", "B"], (0, 0, img.shape[1] - 1, img.shape[0] - 1))
    click.echo(table)


def _temporal(dataset, out, loaded, cross_spec, spps, kinds, scenes, window):
    from ranad_core import evaluate as ev
    from ranad_core.fileutil import atomic_output
    from ranad_core.model.store import load_model, training_window

    if not cross_spec:
        raise click.UsageError("--temporal needs --cross-model")
    cross = load_model(cross_spec)
    if cross.model.config.window <= 1:
        raise RanadError("not a cross-frame model", cross_spec)
    window = window or max(2, training_window(cross))
    found = ev.temporal_scenes(dataset)
    if not found:
        raise RanadError("no scene has references on consecutive frames (make it with --ref-frames all)", dataset)
    os.makedirs(out, exist_ok=True)
    n = len(found[:scenes] if scenes else found) * len(kinds or ("deepz", "deepoid")) * len(spps or found[0][1]["spp"])
    with tqdm(total=n, desc="temporal eval", unit="shot") as bar:
        rows = ev.evaluate_temporal(dataset, loaded.model, cross.model, spps, kinds, scenes, window, bar.update)
    table = ev.temporal_markdown(rows, f"{loaded.model_id} vs {cross.model_id} (window {window}) on "
                                       f"{os.path.basename(os.path.normpath(dataset))}, {len({r['scene'] for r in rows})} scenes")
    with atomic_output(os.path.join(out, "temporal.md")) as tmp:
        with open(tmp, "w") as f:
            f.write(table)
    ev.write_csv(rows, os.path.join(out, "temporal.csv"),
                 ("scene", "kind", "spp", "ref_spp", "method", "flip", "temporal", "seconds"))
    click.echo(table)
