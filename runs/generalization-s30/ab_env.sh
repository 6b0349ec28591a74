#!/bin/bash
# session 30: alternating whole-process timings of a 512x512 crop of bench/denoise.py's synth frame (its
# make_1080p, then tile_to 512x512): numpy's BLAS on two threads (as before), on one (the new default), and on one
# with the cycle collector off (gc.disable, the stand-in that was timed for the gc.freeze adopted)
cd /work/data/s30/frame && . /work/main/.venv/bin/activate
for i in 1 2 3 4 5; do
  for v in blas2 blas1 gcoff; do
    rm -f /tmp/ab.exr
    case $v in
      blas2) /usr/bin/time -f "$v %e" env OPENBLAS_NUM_THREADS=2 ranad denoise synth512.exr -o /tmp/ab.exr \
                 > /dev/null 2>> /tmp/ab_times.txt ;;
      blas1) /usr/bin/time -f "$v %e" ranad denoise synth512.exr -o /tmp/ab.exr > /dev/null 2>> /tmp/ab_times.txt ;;
      gcoff) /usr/bin/time -f "$v %e" python -c "import gc, sys; gc.disable(); \
                 sys.argv = ['ranad', 'denoise', 'synth512.exr', '-o', '/tmp/ab.exr']; \
                 from ranad_cli.main import main; main()" > /dev/null 2>> /tmp/ab_times.txt ;;
    esac
  done
done
