# session 23's chains: sourced by them (bash). The data folder, the environment, and `ev NAME SET MODEL`, one held-out
# evaluation into s23/ev_NAME_SET (skipped when done), the command every single-frame row of the study comes from.
cd /work/data
. /work/main/.venv/bin/activate
ev() { [ -f s23/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s23/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s23/ev_$1_$2.log 2>&1; }
