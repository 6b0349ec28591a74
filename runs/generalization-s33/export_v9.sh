#!/bin/bash
# the v9 candidate: c128f3-t1 exported with v6's halo frames (runs/generalization-s23/export.sh) but for the fog
# frame, whose Gaussian-filtered set was not in this session's data folder: scene 0 of heldout_g1fog_boxsob instead
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
H=()
for s in 0 1 2 3; do
  for k in deepz deepoid; do H+=(--measure-halo heldout_g1sg8/scene_000$s/$k/noisy_spp16.0000.exr); done
done
for s in 0 1; do H+=(--measure-halo heldout_g1sg8/scene_000$s/deepz/noisy_spp4.0000.exr); done
for s in 0 1; do H+=(--measure-halo train_g33_win/scene_000$s/deepz/noisy_spp16.0000.exr); done
H+=(--measure-halo heldout_g1fog_boxsob/scene_0000/deepz/noisy_spp16.0000.exr)
( time ranad export $R/cpu-small-pdl-gza-c128f3-t1 -o /work/main/ranad_core/weights/cpu-small-pdl-gza-v9.safetensors \
    "${H[@]}" ) > $S/export_v9.log 2>&1
