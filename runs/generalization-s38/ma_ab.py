"""The guard of _match_args three ways on the saved tile (every pair; the neighbours' pairs; without the key gather),
the same booleans, best of 6 interleaved rounds."""
import sys, time, types, torch
sys.path.insert(0, "/work/main")
from ranad_core.model.matching import pixel_pairs, consistent
from ranad_core.model.inputs import GUIDE_WIDTH
d = torch.load("/tmp/s38/match_args.pt", weights_only=False)
frames = [types.SimpleNamespace(layout=l) for l in d["frames_layouts"]]
centre = d["centre"]; keys = d["keys"]; gather = d["gather"]; frame = d["frame"]; feats = d["feats"]
c = frames[centre]
rows = torch.empty_like(gather); rows[gather] = torch.arange(gather.numel())
first = sum(f.layout.bins for f in frames[:centre]); own_rows = rows[first:first + c.layout.bins]
qi, kj = pixel_pairs(c.layout.pixels, keys)
def v0():
    allg = torch.cat([f[:, -GUIDE_WIDTH:] for f in feats])[gather]
    return (kj == own_rows[qi]) | ((frame[kj] != centre) & consistent(allg[own_rows][qi], allg[kj]))
def v1():
    allg = torch.cat([f[:, -GUIDE_WIDTH:] for f in feats])[gather]
    ok = kj == own_rows[qi]
    other = torch.nonzero(frame[kj] != centre).squeeze(1)
    ok[other] |= consistent(allg[own_rows[qi[other]]], allg[kj[other]])
    return ok
def v2():
    g = torch.cat([f[:, -GUIDE_WIDTH:] for f in feats])
    ok = kj == own_rows[qi]
    other = torch.nonzero(frame[kj] != centre).squeeze(1)
    ok[other] |= consistent(g[qi[other] + first], g[gather[kj[other]]])
    return ok
with torch.inference_mode():
    r = [v0(), v1(), v2()]
    print("equal:", torch.equal(r[0], r[1]), torch.equal(r[0], r[2]))
    best = [1e9] * 3
    for _ in range(6):
        for i, f in enumerate((v0, v1, v2)):
            t = time.perf_counter(); f(); best[i] = min(best[i], time.perf_counter() - t)
    print(" ".join(f"v{i} {b*1e3:.1f} ms" for i, b in enumerate(best)))
