"""Diagnostic (session 33): how much of flat OIDN's HDR-FLIP on a set is the reference's own noise? Per deep-Z scene
and spp: FLIP(reference, OIDN(reference)) (the 1024-spp reference's residual noise as FLIP sees it, with OIDN's
small bias at that sample count), beside FLIP(reference, OIDN(noisy)); means over the scenes.
Usage: python ref_floor.py SET...   (run in the data folder)"""
import collections
import sys

import numpy as np

from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.exr import read_deep
from ranad_core.train.data import find_pairs

print("| set | spp | FLIP(ref, OIDN(ref)) | FLIP(ref, OIDN(noisy)) | share |")
print("|---|---|---|---|---|")
for folder in sys.argv[1:]:
    acc = collections.defaultdict(list)
    for p in find_pairs([folder]):
        if p.kind != "deepz" or p.spp not in (4, 16):
            continue
        ref = read_deep(p.reference)
        fr = metrics.flat_rgb(ref)
        acc[p.spp].append((metrics.flip(fr, oidn_flat(ref)), metrics.flip(fr, oidn_flat(read_deep(p.noisy)))))
    for spp in sorted(acc):
        a, b = np.mean(acc[spp], axis=0)
        print(f"| {folder} | {spp} | {a:.4f} | {b:.4f} | {a / b:.2f} |", flush=True)
