#!/bin/bash
# export RUN -> OUT.safetensors with v6's halo frames (its card): scenes 0-3 of heldout_g1sg8 at 16 spp, both kinds,
# scenes 0-1 at 4 spp deep-Z, train_g33_win scenes 0-1 and heldout_g1fog scene 0 at 16 spp deep-Z
# usage: export.sh RUN OUT.safetensors [EXPORT OPTIONS]   (run in the data folder)
. /work/main/.venv/bin/activate
H=()
for s in 0 1 2 3; do for k in deepz deepoid; do H+=(--measure-halo heldout_g1sg8/scene_000$s/$k/noisy_spp16.0000.exr); done; done
for s in 0 1; do H+=(--measure-halo heldout_g1sg8/scene_000$s/deepz/noisy_spp4.0000.exr); done
for s in 0 1; do H+=(--measure-halo train_g33_win/scene_000$s/deepz/noisy_spp16.0000.exr); done
H+=(--measure-halo heldout_g1fog/scene_0000/deepz/noisy_spp16.0000.exr)
ranad export "$1" -o "$2" "${@:3}" "${H[@]}"
