"""binmerge.merge of the saved neighbour against the session start's (a copy of its binmerge.py as
/tmp/s38/binmerge_old.py, imports made absolute), alternating, with a byte comparison."""
import sys, time, pickle
sys.path.insert(0, "/tmp/s38")
import binmerge_old as old
import ranad_core.binmerge as bm
srt, groups = pickle.load(open("/tmp/s38/mergecase.pkl", "rb"))
print(srt.values.dtype, srt.values.shape, srt.values.flags['C_CONTIGUOUS'], groups.index.dtype, groups.trans.dtype)
for rep in range(4):
    t = time.perf_counter(); a = old.merge(srt, groups)
    t1 = time.perf_counter(); b = bm.merge(srt, groups); t2 = time.perf_counter()
    print(f"old {t1-t:.3f} new {t2-t1:.3f}", a.values.tobytes() == b.values.tobytes())
import cProfile
cProfile.run("bm.merge(srt, groups)", sort="tottime")
