"""Time spent in each C++ extension entry point during `ranad denoise` (session 24 investigation).
Usage: python extprof.py FRAME.exr [DENOISE OPTIONS]   (with ranad_core importable)"""
import sys, time, collections
import ranad_core.rana.extension as E
real = E.cpu_extension_or_none()
T = collections.defaultdict(float); N = collections.Counter(); P = collections.Counter()
class Proxy:
    def __getattr__(self, name):
        f = getattr(real, name)
        if not callable(f):
            return f
        def w(*a, **k):
            t = time.perf_counter(); r = f(*a, **k); T[name] += time.perf_counter() - t; N[name] += 1
            if name == "forward":
                P[(a[0].shape[1], a[0].shape[2], a[2].shape[2], int(a[10]))] += time.perf_counter() - t
            return r
        return w
proxy = Proxy()
import ranad_core.model.fused as F, ranad_core.rana.op as O, ranad_core.baselines as B
F.cpu_extension_or_none = O.cpu_extension_or_none = E.cpu_extension_or_none = lambda: proxy
O.load_cpu_extension = lambda: proxy
from ranad_cli.main import cli
t = time.time()
try:
    cli.main(["denoise", sys.argv[1], "-o", "/tmp/extprof_out.exr"] + sys.argv[2:], standalone_mode=False)
except SystemExit:
    pass
print("wall", round(time.time() - t, 2))
for k, v in sorted(T.items(), key=lambda kv: -kv[1]):
    print(f"{k:24s} {v:7.2f} s {N[k]:5d} calls")
for k, v in sorted(P.items(), key=lambda kv: -kv[1]):
    print("forward H,dk,dv,R", k, round(v, 2))
