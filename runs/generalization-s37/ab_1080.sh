#!/bin/bash
# Old and new code on the held-out 1080p frame, interleaved (old, new, flat OIDN per round), one process each:
#   bash runs/generalization-s37/ab_1080.sh OLD_TREE NEW_TREE FRAME1080.exr ROUNDS
# OLD_TREE / NEW_TREE: checkouts of the two commits (git worktree add /tmp/old_wt COMMIT); FRAME1080.exr: the frame
# bench/denoise.py --frame tiles to 1080p (written by `python bench/denoise.py --frame F` or tile_to). Prints wall
# seconds and peak resident MB per run; the flat OIDN command and its environment are bench/denoise.py's (read,
# flatten, OIDN; numpy without huge pages, BLAS on one thread, as the ranad command sets for itself).
# `python -P`: without it, `python -m` puts the working directory ahead of PYTHONPATH, so a run from a checkout
# measured that checkout twice (session 39).
set -eu
old=$1; new=$2; frame=$3; rounds=${4:-3}
out=$(mktemp -d)
oidn="import sys, numpy as np, pyoidn; from ranad_core.exr import read_deep; from ranad_core import metrics; \
img = read_deep(sys.argv[1]); flat = np.ascontiguousarray(metrics.flat_rgb(img), np.float32); \
pyoidn.denoise(np.maximum(flat, 0), hdr=True)"
for r in $(seq "$rounds"); do
  for tree in "$old" "$new"; do
    /usr/bin/time -f "$tree %e s %M KB" env PYTHONPATH="$tree" python -P -m ranad_cli denoise "$frame" \
      -o "$out/o.exr" --threads 2 >/dev/null 2>"$out/err" || { cat "$out/err"; exit 1; }
    tail -1 "$out/err"
  done
  /usr/bin/time -f "flat-oidn %e s %M KB" env PYTHONPATH="$new" NUMPY_MADVISE_HUGEPAGE=0 OPENBLAS_NUM_THREADS=1 \
    OMP_NUM_THREADS=2 python -P -c "$oidn" "$frame" 2>&1 | tail -1
done
rm -rf "$out"
