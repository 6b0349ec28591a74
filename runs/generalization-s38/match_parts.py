"""The matching step's parts timed one by one on the saved tile (and rows_pair_sum against torch's index_add)."""
import sys, time, types, torch
sys.path.insert(0, "/work/main")
from ranad_core.model.store import load_model
from ranad_core.model import fused
from ranad_core.model.matching import segment_softmax
d = torch.load("/tmp/s38/match_args.pt", weights_only=False)
m = load_model("cpu-small-pdl-gza-xg-v9").model
frames = [types.SimpleNamespace(layout=l) for l in d["frames_layouts"]]
c = d["centre"]
out = m._match_args(d["feats"], frames, c, d["keys"], d["gather"], d["frame"])
feats = out["feats"]; allf = torch.cat(feats)[d["gather"]]; q = feats[c]; own = out["own"]; qi, kj = out["pairs"]
v = torch.randn(allf.shape[0], 6)
k = m.temporal["diffuse"]
def T(name, f, n=5):
    best = 1e9
    for _ in range(n):
        t = time.perf_counter(); r = f(); best = min(best, time.perf_counter() - t)
    print(f"{name}: {best*1e3:.1f} ms", flush=True); return r
with torch.inference_mode():
    pq = T("proj q", lambda: k.proj(q))
    pk = T("proj k", lambda: k.proj(allf))
    a = T("pq[qi]", lambda: pq[qi]); b = T("pk[kj]", lambda: pk[kj])
    x = T("cat", lambda: torch.cat([(a - b).abs(), a * b], 1))
    lg = T("relu_mlp", lambda: fused.relu_mlp(k.score, x).squeeze(1))
    mask = T("own mask", lambda: (kj == own[qi]).to(lg.dtype))
    lg2 = lg + k.self_bonus * mask
    w = T("softmax", lambda: segment_softmax(lg2, qi, q.shape[0]))
    vk = T("values[kj]", lambda: v[kj])
    T("weight*vals", lambda: w.unsqueeze(1).to(v.dtype) * vk)
    wv = w.unsqueeze(1).to(v.dtype) * vk
    T("index_add", lambda: v.new_zeros(q.shape[0], v.shape[1]).index_add(0, qi, wv))
    print("qi sorted:", bool((qi[1:] >= qi[:-1]).all()), "P", qi.numel(), "Nq", q.shape[0])
    import ranad_core.rana.extension as ext
    e = ext.cpu_extension_or_none()
    r1 = T("rows_pair_sum", lambda: e.rows_pair_sum(w, v, qi, kj, q.shape[0]))
    r0 = T("torch sum",
           lambda: v.new_zeros(q.shape[0], v.shape[1]).index_add(0, qi, w.unsqueeze(1).to(v.dtype) * v[kj]))
    print("equal", torch.equal(r0, r1))
