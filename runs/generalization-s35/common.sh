# sourced by session 35's chains: session 34's common.sh (data folder, environment, syn, ev, trn, evt, xgt, V9) with
# logs and evaluations in s35
. "$(dirname "${BASH_SOURCE[0]}")/../generalization-s34/common.sh"
S=s35
mkdir -p $S
# the training families (every preset but the held-out fog, interior, glass and layers)
FAMILIES="--preset easy --preset medium --preset deep-heavy --preset studio --preset thin --preset textured
    --preset exterior --preset organic --preset motion --preset windows"
# the held-out sets of v9's card and session 34's six further ones, then the two in-family sets
SETS="heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob heldout_g1sg8
    heldout_g1ac8 heldout_g1sp heldout_g1fog heldout_g1w4 heldout_g1fog_rot heldout_g1int8_rot heldout_g1sg8_rot
    heldout_g1sg8_yaw infam_g36_box infam_g36_boxsob"
