# sourced by session 28's chains: session 27's common.sh (data folder, environment, syn, ev) with logs in s28, and
# what the chains share: the nine held-out sets they score and the fine-tuning options of session 27's t16 recipe
S=s28
. "$(dirname "${BASH_SOURCE[0]}")/../generalization-s27/common.sh"
HELDOUT9="heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob
          heldout_g1sg8 heldout_g1w4 heldout_g1ac8 heldout_g1fog"
T16_POOL="train_g35_boxsob train_g35_boxsob train_g33_win train_g31_sub train_g30_sub"
# (each chain adds --init: v7, or a model grown from it) crop 64, alpha and separation weighted, 4/64/128-spp
# crops twice as often, half the normals turned
T16_OPTS="--crop 64 --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 200
          --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5"
# ev_sets TAG MODEL SET...: ev of MODEL on each SET (skipped once done)
ev_sets() { for s in "${@:3}"; do ev $1 $s $2; done; }
