# sourced by session 27's and later chains: the data folder, the environment, and the two steps every chain repeats;
# logs and evaluations go to the folder $S of the data folder (s27 unless the chain sets it)
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
R=/work/main/runs
S=${S:-s27}
# syn NAME OPTIONS...: ranad synth of 128x128 single frames (FRAMES=3 syn ...: shots of 3) with 1024-spp references
# into NAME (skipped once done)
syn() { [ -f $S/$1.done ] || { ( time ranad synth -o $1 --size 128 --frames ${FRAMES:-1} --ref-spp 1024 --workers 2 \
    "${@:2}" ) > $S/synth_$1.log 2>&1 && touch $S/$1.done; }; }
# ev TAG SET MODEL: ranad eval of SET with the held-out families, into $S/ev_TAG_SET (skipped once done)
ev() { [ -f $S/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o $S/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > $S/ev_$1_$2.log 2>&1; }
# trn NAME OPTIONS...: ranad train OPTIONS into runs/cpu-small-pdl-gza-NAME, logged to $S/train_NAME.log (skipped
# once done)
trn() { [ -f $S/$1.done ] || { ( time ranad train "${@:2}" -o $R/cpu-small-pdl-gza-$1 ) > $S/train_$1.log 2>&1 \
    && touch $S/$1.done; }; }
# v8's fine-tune recipe (ranad_core/weights/cpu-small-pdl-gza-v8.md) from v8's weights, without its data, --steps and
# --crop (sessions 32 and 33 varied those), and v8's training pool
V8_OPTS="--config cpu-small-pdl-gza --lr 1e-4 --seed 28 --init cpu-small-pdl-gza-v8 --loss-weight alpha=2
    --loss-weight separation=1 --loss-weight flip=2 --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=2
    --spp-weight 128=2 --rotate-normals 0.5"
V8_POOL="train_g35_boxsob train_g35_boxsob train_g33_win train_g31_sub train_g30_sub"
