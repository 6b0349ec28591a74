"""Bins that `ranad denoise` would merge (binmerge, default gap) in every noisy file of datasets: ranad's own
binning should give none. usage: count_merges.py DATASET... [--gap G]"""
import sys
from pathlib import Path

from ranad_core import binmerge
from ranad_core.channels import canonical, detect
from ranad_core.exr import read_deep

args = sys.argv[1:]
gap = binmerge.MERGE_GAP
if "--gap" in args:
    i = args.index("--gap")
    gap = float(args[i + 1])
    del args[i:i + 2]
for root in args:
    files = sorted(Path(root).glob("scene_*/*/noisy_spp*.exr"))
    bins = merged = 0
    for f in files:
        img = read_deep(f)
        srt, perm = canonical(img, detect(img))[0].sorted()
        g = binmerge.groups_of(srt, img, perm, gap)
        bins += img.num_bins
        merged += 0 if g is None else img.num_bins - g.merged
    print(f"{root}: {len(files)} files, {bins} bins, {merged} merged away at gap {gap}")
