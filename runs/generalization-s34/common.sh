# sourced by session 34's chains: session 27's common.sh (data folder, environment, syn, ev, trn) with logs and
# evaluations in s34, and the shipped single-frame default's file
S=s34
. "$(dirname "${BASH_SOURCE[0]}")/../generalization-s27/common.sh"
mkdir -p $S
V9=/work/main/ranad_core/weights/cpu-small-pdl-gza-v9.safetensors
# evt TAG SET MODEL CROSS: ranad eval --temporal of the shot set SET with the pair MODEL + CROSS into $S/evt_TAG_SET
evt() { [ -f $S/evt_$1_$2/temporal.md ] || ( time ranad eval $2 -o $S/evt_$1_$2 --temporal --model $3 \
    --cross-model $4 ) > $S/evt_$1_$2.log 2>&1; }
