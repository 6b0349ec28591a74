"""`ranad denoise ...` that saves the first merged neighbour (sorted image and groups) to /tmp/s38/mergecase.pkl, the
input of bench_merge.py."""
import sys, pickle
import ranad_core.binmerge as bm
new_merge = bm.merge
done = [0]
def merge(srt, groups):
    if not done[0]:
        with open("/tmp/s38/mergecase.pkl", "wb") as f:
            pickle.dump((srt, groups), f, protocol=5)
        done[0] = 1
    return new_merge(srt, groups)
bm.merge = merge
from ranad_cli.main import cli
cli(sys.argv[1:], standalone_mode=False)
