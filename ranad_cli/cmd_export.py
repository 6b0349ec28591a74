"""``ranad export``: a training run's checkpoint as a shippable .safetensors model."""

from __future__ import annotations

import click


@click.command("export")
@click.argument("run")
@click.option("-o", "--out", "out", required=True, type=click.Path(dir_okay=False),
              help="The .safetensors file to write (with the model config and provenance as metadata).")
@click.option("--note", "notes", multiple=True, metavar="KEY=VALUE", help="Extra metadata, e.g. data=data_v1.")
@click.option("--measure-halo", "halo_frames", multiple=True, type=click.Path(exists=True, dir_okay=False),
              metavar="FRAME",
              help="Deep EXR frames (repeat the option) to measure the model's tile halo on: the smallest halo whose "
                   "32-px tiles match the whole frame (relative difference 1e-5 on average, 1% at worst; stored as "
                   "metadata 'halo', the default of `ranad denoise --halo`). Frames unlike the model's users' "
                   "make a halo that is too small for them: measure on several kinds of scene.")
@click.option("--interpolate", "interpolate", metavar="MODEL=T", default=None,
              help="Write (1 - T) x RUN's weights + T x MODEL's (a model of the same configuration, e.g. the one "
                   "RUN was fine-tuned from; 0 <= T <= 1): weights between a model and its fine-tuned descendant "
                   "often hold up better on renders neither was trained on. The halo is measured on the result.")
def export_cmd(run, out, notes, halo_frames, interpolate):
    """Export RUN (a training run folder, its checkpoint.pt, a .safetensors file or a shipped model's name, whose
    metadata is then updated) as weights `ranad denoise --model` can load."""
    import os
    import tempfile

    from ranad_core.model.store import export_weights, load_model

    extra = {}
    for n in notes:
        if "=" not in n:
            raise click.BadParameter(f"expected KEY=VALUE, got {n!r}", param_hint="--note")
        k, v = n.split("=", 1)
        extra[k] = v
    mix = _interpolation(interpolate)
    scratch = None
    try:
        if mix is not None and halo_frames:   # the halo is the interpolated weights': they go to a scratch file
            fd, scratch = tempfile.mkstemp(suffix=".safetensors", dir=os.path.dirname(os.path.abspath(out)))
            os.close(fd)
            export_weights(run, scratch, interpolate=mix)
            run, mix = scratch, None
        if halo_frames:
            extra.update(_measured_halo(load_model(run).model, halo_frames))
        export_weights(run, out, extra, interpolate=mix)
    finally:
        if scratch is not None and os.path.exists(scratch):
            os.remove(scratch)
    click.echo(f"wrote {out} ({load_model(out).model_id})")


def _interpolation(option: str | None) -> tuple[str, float] | None:
    """--interpolate MODEL=T as (MODEL, T), or None."""
    if option is None:
        return None
    other, _, t = option.rpartition("=")
    try:
        weight = float(t)
    except ValueError:
        weight = -1.0
    if not other or not 0.0 <= weight <= 1.0:
        raise click.BadParameter(f"expected MODEL=T with 0 <= T <= 1, got {option!r}", param_hint="--interpolate")
    return other, weight


def _measured_halo(model, halo_frames) -> dict:
    """The metadata of the halo measured on `halo_frames` (halo.measure_halo), reporting each step."""
    from ranad_core.denoise import halo_for_bound
    from ranad_core.exr import read_deep
    from ranad_core.halo import measure_halo

    images = [read_deep(f) for f in halo_frames]
    halo, _ = measure_halo(model, images,
                           progress=lambda h, m, w: click.echo(f"halo {h:3d} px: mismatch mean {m:.1e}, "
                                                               f"worst bin {w:.1e}", err=True))
    click.echo(f"measured halo: {halo} px (the receptive-field bound: {halo_for_bound(model)} px)")
    return {"halo": str(halo), "halo_measured_on": ", ".join(str(f) for f in halo_frames)}
