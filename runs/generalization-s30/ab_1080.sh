#!/bin/bash
# session 30: issue 27's two frames, the commit before this session's speed changes (a worktree at /tmp/wt_old, with
# this session's bench/denoise.py) against the new one, in the order old, new, new, old. The old runs, ranad and its
# baselines, get numpy's BLAS on its default two threads, as before; the new ones on one.
cd /work/data && . /work/main/.venv/bin/activate
F=heldout_g1_s5/scene_0005/deepz/noisy_spp16.0000.exr
for root in /tmp/wt_old /work/main /work/main /tmp/wt_old; do
  echo "== $root held-out"; B=""; [ $root = /tmp/wt_old ] && B="env OPENBLAS_NUM_THREADS=2"
  $B python $root/bench/denoise.py --real "" --frame $F 2>&1 | grep -v "^made"
done
for root in /tmp/wt_old /work/main; do
  echo "== $root synth"; B=""; [ $root = /tmp/wt_old ] && B="env OPENBLAS_NUM_THREADS=2"
  $B python $root/bench/denoise.py --real "" 2>&1 | grep -v "^made"
done
