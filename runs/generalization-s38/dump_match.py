"""`ranad denoise ...` that saves the first tile's matching-step arguments to /tmp/s38/match_args.pt (the input of
match_bench.py, match_parts.py and ma_ab.py): python dump_match.py denoise SHOT -o OUT --model cpu-small-pdl-gza-xg-v9
--frames 1-3"""
import sys, torch
import ranad_core.model.crossframe as cf
orig = cf.CrossFrameRaNAD._match_args
done = [0]
def ma(self, feats, frames, centre, keys, gather, frame):
    out = orig(self, feats, frames, centre, keys, gather, frame)
    if not done[0]:
        torch.save({"feats": feats, "frames_layouts": [f.layout for f in frames], "centre": centre, "keys": keys,
                    "gather": gather, "frame": frame, "out": out}, "/tmp/s38/match_args.pt")
        done[0] = 1
    return out
cf.CrossFrameRaNAD._match_args = ma
from ranad_cli.main import cli
cli(sys.argv[1:], standalone_mode=False)
