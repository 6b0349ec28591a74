"""``ranad info``: what is in a deep EXR (or a sequence of them)."""

from __future__ import annotations

import json

import click

from ranad_core.binmerge import MERGE_GAP
from ranad_core.darkness import DARK_RADIUS

from ranad_core.exr.inspect import describe
from ranad_core.exr.sequence import expand_inputs



def _size(n: int) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return str(n)


def _print_text(d: dict) -> None:
    click.echo(f"{d['file']}  ({_size(d['file_size'])}{', multi-part' if d['multipart'] else ''})")
    for p in d["parts"]:
        name = f" '{p['name']}'" if p["name"] else ""
        w, h = p["resolution"]
        levels = (f", {p['levels']} levels (ranad reads the full-resolution one)"
                  if p.get("levels") not in (None, "one") else "")
        click.echo(f"  part {p['index']}{name}: {p['type']}, {w}x{h}, compression {p['compression']}{levels}")
        click.echo(f"    data window {tuple(p['data_window'])}, display window {tuple(p['display_window'])}")
        chans = ", ".join(f"{n}:{t}" for n, t in p["channels"].items())
        click.echo(f"    channels ({len(p['channels'])}): {chans}")
        if not p["deep"]:
            click.echo("    flat image (not deep)")
            continue
        dc = p.get("denoise_channels", {})
        skip = ("mode", "motion", "motion_candidates")
        layers = ", ".join(f"{k}={v}" for k, v in dc.items() if k not in skip and v != "-")
        click.echo(f"    ranad denoise reads: {dc.get('mode', '?')}" + (f" ({layers})" if layers else ""))
        if "motion" in dc:
            hint = dc.get("motion_candidates")
            click.echo(f"    motion channels: {dc['motion']}"
                       + (f" (not mapped; may hold motion: {', '.join(hint)}: --map motion_prev=X,Y)" if hint else ""))
        if "bins_per_pixel" not in p:
            continue
        b = p["bins_per_pixel"]
        click.echo(f"    {p['kind_guess']} (guess); {p['bins']} bins; per pixel min {b['min']}, "
                   f"mean {b['mean']:.2f} (covered {b['mean_covered']:.2f}), max {b['max']}; "
                   f"{100 * p['empty_pixels']:.1f}% empty")
        click.echo(f"    volume samples: {'yes' if p['volume_samples'] else 'no'}; deepImageState: "
                   f"{p['deepImageState'] or 'absent'} (measured: {p['measured_state']})")
        ids = ", ".join(p["id_channels"]) or "none"
        click.echo(f"    id channels: {ids}; id manifest: {'yes' if p['id_manifest'] else 'no'}")
        if p.get("thin_bins"):
            share = 100 * p["thin_bins"] / max(p["bins"], 1)
            click.echo(f"    thin bins: {p['thin_bins']} ({share:.1f}%) lie within {100 * MERGE_GAP:g}% in depth of "
                       "the bin in front (same ids): ranad denoise merges them (--bin-merge)")
        if p.get("dark_pixels"):
            share = 100 * p["dark_pixels"] / max(w * h, 1)
            side = 2 * DARK_RADIUS + 1
            click.echo(f"    kept black: {p['dark_pixels']} pixels ({share:.1f}%) hold bins of exactly black "
                       f"{side}x{side} windows or of holdout objects (no bin lit): ranad denoise keeps their colour 0 "
                       "(--dark-radius)")
        if p["nonfinite_values"]:
            click.echo(f"    WARNING: {p['nonfinite_values']} NaN/Inf sample values")


@click.command("info")
@click.argument("inputs", nargs=-1, required=True)
@click.option("--frames", help="Frame range for patterns, e.g. 1001-1010 or 1001-1100x2 (default: all on disk).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document (a list, one entry per file).")
@click.option("--no-stats", is_flag=True, help="Headers only: skip reading the samples (fast on big files).")
@click.option("--map", "maps", multiple=True, metavar="LAYER=CHANNELS",
              help="Show the channels `ranad denoise --map ...` would read (same syntax).")
@click.option("--preset", default=None, type=click.Choice(["renderman", "arnold", "karma", "vray", "redshift"]),
              help="Show the channels `ranad denoise --preset ...` would read.")
def info_cmd(inputs: tuple[str, ...], frames: str | None, as_json: bool, no_stats: bool, maps, preset) -> None:
    """Describe deep EXR files: INPUTS are files or patterns (name.####.exr, name.%04d.exr, name.@@@@.exr).

    Shows resolution, windows, parts, channels and their types, the channels `ranad denoise` reads (layers and
    per-bin motion), deep-Z vs deep-OID guess, bins per pixel (min/mean/max, share of empty pixels), volume
    samples, deepImageState, id channels, id manifest, compression and file size.
    """
    from ranad_core.channels import mapping_options

    overrides = mapping_options(maps, preset)
    results = [describe(f.path, stats=not no_stats, overrides=overrides) for f in expand_inputs(list(inputs), frames)]
    if as_json:
        click.echo(json.dumps(results, indent=2))
    else:
        for d in results:
            _print_text(d)
