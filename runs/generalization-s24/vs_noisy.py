# usage: python runs/generalization-s24/vs_noisy.py EVAL_FOLDER...   (folders of `ranad eval`)
"""Per held-out set, family and spp: mean flat FLIP and edit FLIP of ranad and of flat OIDN over the noisy input's
(deep-Z, exposure 0; ratios of means over the scenes), and how many scenes ranad leaves worse than its input."""
import csv, collections, sys
for folder in sys.argv[1:]:
    acc = collections.defaultdict(lambda: collections.defaultdict(list))
    for r in csv.DictReader(open(folder + "/eval.csv")):
        if r["kind"] == "deepz" and r["exposure"] in ("0", "+0"):
            acc[(r["family"], int(r["spp"]))][r["method"]].append((r["scene"], float(r["flip"]), float(r["comp_flip"])))
    for (fam, spp), m in sorted(acc.items()):
        mean = lambda k, i: sum(x[i] for x in m[k]) / len(m[k])
        worse = sum(1 for a, n in zip(m["ranad"], m["noisy"]) if a[1] > n[1])
        print(f"{folder.split('/')[-1]:28s} {fam:7s} {spp:4d} spp: ranad flat {mean('ranad', 1) / mean('noisy', 1):.3f} "
              f"edit {mean('ranad', 2) / mean('noisy', 2):.3f} of noisy, OIDN flat {mean('oidn', 1) / mean('noisy', 1):.3f}; "
              f"ranad's flat worse than noisy in {worse}/{len(m['ranad'])}")
