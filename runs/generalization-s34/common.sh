# sourced by session 34's chains: session 27's common.sh (data folder, environment, syn, ev, trn) with logs and
# evaluations in s34, and the shipped single-frame default's file
S=s34
. "$(dirname "${BASH_SOURCE[0]}")/../generalization-s27/common.sh"
mkdir -p $S
V9=/work/main/ranad_core/weights/cpu-small-pdl-gza-v9.safetensors
# evt TAG SET MODEL CROSS: ranad eval --temporal of the shot set SET with the pair MODEL + CROSS into $S/evt_TAG_SET
evt() { [ -f $S/evt_$1_$2/temporal.md ] || ( time ranad eval $2 -o $S/evt_$1_$2 --temporal --model $3 \
    --cross-model $4 ) > $S/evt_$1_$2.log 2>&1; }
# xgt N INIT: xg-v8's recipe (ranad_core/weights/cpu-small-pdl-gza-xg-v8.md) on the shots train_g3 and train_g3s
# from the single-frame weights INIT, frozen, into runs/cpu-small-pdl-gza-xg-tN (skipped once done), exported with
# v6's halo frames (generalization-s23/export.sh) to $S/xgN.safetensors
xgt() {
  [ -f $S/xg$1.done ] || { ( time OMP_NUM_THREADS=2 ranad train train_g3 train_g3s -o $R/cpu-small-pdl-gza-xg-t$1 \
      --config cpu-small-pdl-gza-xg --init $2 --window 3 --steps 800 --crop 64 --lr 5e-4 --seed 0 --freeze-spatial \
      --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 100 ) > $S/train_xg$1.log 2>&1 \
      && touch $S/xg$1.done; } || return 1
  [ -f $S/xg$1.safetensors ] || bash $R/generalization-s23/export.sh $R/cpu-small-pdl-gza-xg-t$1 \
      $S/xg$1.safetensors > $S/export_xg$1.log 2>&1
}
