"""Deep-Z ratios of `ranad eval` tables: flat FLIP / OIDN's, edit FLIP and edit SMAPE / OIDN+recolour's, over all
scenes and without scene_0000 and scene_0002 of heldout_g1ac(_fine), where the finely binned references make the
edit's HDR-FLIP degenerate (README here). usage: compare.py NAME=eval.csv ..."""
import csv
import sys

import numpy as np

EXCLUDED = {"scene_0000", "scene_0002"}


def load(path):
    return {(r["scene"], r["spp"], r["method"]): r for r in csv.DictReader(open(path)) if r["kind"] == "deepz"}


def ratio(d, scenes, spp, key, base):
    return (np.mean([float(d[(s, spp, "ranad")][key]) for s in scenes])
            / np.mean([float(d[(s, spp, base)][key]) for s in scenes]))


print("| table | spp | flat FLIP vs OIDN | edit FLIP vs recolour | edit SMAPE vs recolour | edit FLIP, 14 scenes |")
print("|---|---|---|---|---|---|")
for arg in sys.argv[1:]:
    name, path = arg.split("=", 1)
    d = load(path)
    for spp in sorted({k[1] for k in d}, key=int):
        scenes = sorted({k[0] for k in d if k[1] == spp})
        kept = [s for s in scenes if s not in EXCLUDED]
        print(f"| {name} | {spp} | {ratio(d, scenes, spp, 'flip', 'oidn'):.3f} | "
              f"{ratio(d, scenes, spp, 'comp_flip', 'recolour'):.3f} | "
              f"{ratio(d, scenes, spp, 'comp_smape', 'recolour'):.3f} | "
              f"{ratio(d, kept, spp, 'comp_flip', 'recolour'):.3f} |")
