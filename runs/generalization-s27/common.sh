# sourced by session 27's chains: the data folder, the environment, and the two steps every chain repeats
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
R=/work/main/runs
# syn NAME OPTIONS...: ranad synth of 128x128 single frames with 1024-spp references into NAME (skipped once done)
syn() { [ -f s27/$1.done ] || { ( time ranad synth -o $1 --size 128 --frames 1 --ref-spp 1024 --workers 2 \
    "${@:2}" ) > s27/synth_$1.log 2>&1 && touch s27/$1.done; }; }
# ev TAG SET MODEL: ranad eval of SET with the held-out families, into s27/ev_TAG_SET (skipped once done)
ev() { [ -f s27/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s27/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s27/ev_$1_$2.log 2>&1; }
