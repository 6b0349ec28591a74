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
def export_cmd(run, out, notes, halo_frames):
    """Export RUN (a training run folder, its checkpoint.pt, a .safetensors file or a shipped model's name, whose
    metadata is then updated) as weights `ranad denoise --model` can load."""
    from ranad_core.model.store import export_weights, load_model

    extra = {}
    for n in notes:
        if "=" not in n:
            raise click.BadParameter(f"expected KEY=VALUE, got {n!r}", param_hint="--note")
        k, v = n.split("=", 1)
        extra[k] = v
    if halo_frames:
        from ranad_core.denoise import halo_for_bound
        from ranad_core.exr import read_deep
        from ranad_core.halo import measure_halo

        model = load_model(run).model
        images = [read_deep(f) for f in halo_frames]
        halo, _ = measure_halo(model, images,
                               progress=lambda h, m, w: click.echo(f"halo {h:3d} px: mismatch mean {m:.1e}, "
                                                                   f"worst bin {w:.1e}", err=True))
        extra["halo"] = str(halo)
        extra["halo_measured_on"] = ", ".join(str(f) for f in halo_frames)
        click.echo(f"measured halo: {halo} px (the receptive-field bound: {halo_for_bound(model)} px)")
    export_weights(run, out, extra)
    click.echo(f"wrote {out} ({load_model(out).model_id})")
