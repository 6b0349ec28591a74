"""Times _match_args and the 4 MatchKernel calls of one real tile; checks outputs against saved ones."""
import sys, time, types, torch
sys.path.insert(0, "/work/main")
from ranad_core.model.store import load_model
d = torch.load("/tmp/s38/match_args.pt", weights_only=False)
m = load_model("cpu-small-pdl-gza-xg-v9").model
frames = [types.SimpleNamespace(layout=l) for l in d["frames_layouts"]]
c = d["centre"]
def T(name, f, n=5):
    best = 1e9
    for _ in range(n):
        t = time.perf_counter(); r = f(); best = min(best, time.perf_counter() - t)
    print(f"{name}: {best*1e3:.1f} ms", flush=True); return r
with torch.inference_mode():
    out = T("_match_args", lambda: m._match_args(d["feats"], frames, c, d["keys"], d["gather"], d["frame"]))
    ref = d["out"]
    same = all(torch.equal(a, b) for a, b in zip(out["pairs"], ref["pairs"])) and torch.equal(out["own"], ref["own"])
    print("match_args identical:", same)
    feats = out["feats"]
    allf = torch.cat(feats)[d["gather"]]
    q = feats[c]
    torch.manual_seed(0)
    vals = {n: torch.randn(allf.shape[0], k) for n, k in (("diffuse", 6), ("specular", 3), ("alpha", 1), ("depth", 1))}
    res = {}
    for name, v in vals.items():
        res[name] = T(f"match {name}", lambda: m.temporal[name](q, allf, frames[c].layout.pixels, d["keys"], v,
                                                                own=out["own"], pairs=out["pairs"]))
    if len(sys.argv) > 1 and sys.argv[1] == "save":
        torch.save(res, "/tmp/s38/match_res.pt")
    else:
        ref = torch.load("/tmp/s38/match_res.pt")
        print("match identical:", all(torch.equal(res[k], ref[k]) for k in res))
