# session 26: session 25's cleaner-reference test again with 15 windows scenes instead of 6: v7 fine-tuned on v6's pool
# with train_g33_win's first 15 scenes shown three times, with their 1024-spp references (t13, control) or their
# 4096-spp ones (t14), chain6.sh's recipe otherwise; scored on the Gaussian-4 sets
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
for t in t13:train_g33_win15 t14:train_g33_win_r4k; do
    n=${t%%:*}; w=${t#*:}; R=/work/main/runs/cpu-small-pdl-gzw-$n
    [ -f $R/train.done ] || { ( time ranad train $w $w $w train_g31_sub train_g30_sub -o $R \
        --config cpu-small-pdl-gza --steps 1000 --crop 64 --lr 5e-5 --seed 23 --init cpu-small-pdl-gza-v7 \
        --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 200 \
        --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5 ) > s26/train_gzw_$n.log 2>&1 \
        && touch $R/train.done; }
done
ev() { [ -f s26/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s26/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s26/ev_$1_$2.log 2>&1; }
for s in heldout_g1w4_r4k heldout_g1w4; do
    for n in t13 t14; do ev $n $s /work/main/runs/cpu-small-pdl-gzw-$n; done
done
touch s26/chain3.done
