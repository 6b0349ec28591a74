# session 24's chains: sourced by them (bash). The data folder and the environment.
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
# `ev NAME SET MODEL`: one held-out evaluation into s24/ev_NAME_SET (skipped when done), as session 23's rows
ev() { [ -f s24/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s24/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s24/ev_$1_$2.log 2>&1; }
