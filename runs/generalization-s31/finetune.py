"""Session 31: the fine-tunes of chain2.sh side by side, per held-out set and spp (deep-Z, held-out group, means
over the scenes): flat FLIP / plain OIDN's and edit FLIP / OIDN-then-recolour's of
  v8    the shipped default;
  cp    v8 with the prefiltered-guide prior at inference;
  ctl   v8 fine-tuned 1000 steps on the raw prior (the control);
  cpt   v8 fine-tuned 1000 steps on the prefiltered prior, run with it,
and cpt against OIDN with prefiltered guides (its `oidn-clean` rows).

Usage: python finetune.py SET... (run in the data folder's s31)"""
import sys

from cross import means

print("| set | spp | v8 | cp | ctl | cpt | edit v8 | edit cp | edit ctl | edit cpt | cpt / clean OIDN |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for s in sys.argv[1:]:
    try:
        runs = {t: means(f"ev_{t}_{s}") for t in ("v8", "cp", "ctl", "cpt")}
    except FileNotFoundError:
        continue
    for spp in sorted({k[0] for k in runs["v8"]}):
        o, rc = runs["v8"][(spp, "oidn", "flip")], runs["v8"][(spp, "recolour", "comp")]
        flat = " | ".join(f"{runs[t][(spp, 'ranad', 'flip')] / o:.3f}" for t in runs)
        edit = " | ".join(f"{runs[t][(spp, 'ranad', 'comp')] / rc:.3f}" for t in runs)
        clean = runs["cpt"].get((spp, "oidn-clean", "flip"))
        vs = f"{runs['cpt'][(spp, 'ranad', 'flip')] / clean:.3f}" if clean else "n/a"
        print(f"| `{s}` | {spp} | {flat} | {edit} | {vs} |")
