"""``ranad export``: a training run's checkpoint as a shippable .safetensors model."""

from __future__ import annotations

import click


@click.command("export")
@click.argument("run", type=click.Path(exists=True))
@click.option("-o", "--out", "out", required=True, type=click.Path(dir_okay=False),
              help="The .safetensors file to write (with the model config and provenance as metadata).")
@click.option("--note", "notes", multiple=True, metavar="KEY=VALUE", help="Extra metadata, e.g. data=data_v1.")
def export_cmd(run, out, notes):
    """Export RUN (a training run folder or its checkpoint.pt) as weights `ranad denoise --model` can load."""
    from ranad_core.model.store import export_weights, load_model

    extra = {}
    for n in notes:
        if "=" not in n:
            raise click.BadParameter(f"expected KEY=VALUE, got {n!r}", param_hint="--note")
        k, v = n.split("=", 1)
        extra[k] = v
    export_weights(run, out, extra)
    click.echo(f"wrote {out} ({load_model(out).model_id})")
