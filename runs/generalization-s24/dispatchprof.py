"""Self time of aten ops in the tiles by calling line (TorchDispatchMode), session 24 investigation.
Usage: python dispatchprof.py FRAME.exr [TILE]   (default model, 16-px halo; TILE: None for the whole frame)"""
import sys, time, traceback, collections, torch
from torch.utils._python_dispatch import TorchDispatchMode
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model
from ranad_core.denoise import denoise_frame
torch.set_num_threads(2)
img = read_deep(sys.argv[1])
m = load_model("cpu-small-pdl-gza-v7").model
T = collections.defaultdict(float); N = collections.Counter()
class Mode(TorchDispatchMode):
    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        t = time.perf_counter(); r = func(*args, **(kwargs or {})); dt = time.perf_counter() - t
        fr = [f for f in traceback.extract_stack()[:-1] if "ranad_core" in f.filename]
        where = f"{fr[-1].filename.split('/')[-1]}:{fr[-1].lineno}" if fr else "?"
        T[(str(func.overloadpacket), where)] += dt; N[(str(func.overloadpacket), where)] += 1
        return r
import ranad_core.denoise as D
real = D._tile_inputs
with Mode():
    t = time.time(); denoise_frame(m, img, tile=int(sys.argv[2]) if len(sys.argv) > 2 else None, halo=16); print("wall", time.time() - t)
for k, v in sorted(T.items(), key=lambda kv: -kv[1])[:30]:
    print(f"{v:7.3f} s {N[k]:5d}  {k[0]:28s} {k[1]}")
