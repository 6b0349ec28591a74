# session 25: does training on cleaner references teach the kernels caustics? v7 fine-tuned on v6's pool with the first
# six windows scenes shown three times, with their 1024-spp references (t11, control) or with 4096-spp ones (t12),
# the same seed and recipe otherwise; scored on the Gaussian-4 glass scenes with 4096-spp references and two sets
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
for t in t11:train_g33_win6 t12:train_g33_win_r4k; do
    n=${t%%:*}; w=${t#*:}; R=/work/main/runs/cpu-small-pdl-gzw-$n
    [ -f $R/train.done ] || { ( time ranad train $w $w $w train_g31_sub train_g30_sub -o $R \
        --config cpu-small-pdl-gza --steps 1000 --crop 64 --lr 5e-5 --seed 23 --init cpu-small-pdl-gza-v7 \
        --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 200 \
        --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5 ) > s25/train_gzw_$n.log 2>&1 \
        && touch $R/train.done; }
done
ev() { [ -f s25/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s25/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s25/ev_$1_$2.log 2>&1; }
for s in heldout_g1w4_r4k heldout_g1w4 heldout_g1ac8; do
    for n in t11 t12; do ev $n $s /work/main/runs/cpu-small-pdl-gzw-$n; done
done
for n in t11 t12; do
    [ -f s25/energy_$n.md ] || python s25/energy.py heldout_g1w4_r4k /work/main/runs/cpu-small-pdl-gzw-$n \
        2>/dev/null > s25/energy_$n.md
done
touch s25/chain6.done
