#!/usr/bin/env bash
# Setup 4 (paper): 3 seed views, K in {3, 4, 6} to 15 views, 300 v per stage, 15,000 in total (Blender ship);
# for K = 6 also lite_gs with eps in {0.3, 0.6}.
SCENES="${SCENES:-ship}"
source "$(dirname "$0")/common.sh"
parse_args "$@"
for k in 3 4 6; do
  run_setup setup4 3 "$k" 15 300 15000 "_k$k"
done
for eps in 0.3 0.6; do
  for scene in $SCENES; do
    for seed in $(seq 0 $((SEEDS - 1))); do
      run_one setup4 "$scene" lite_gs "lite_gs_k6_eps$eps" "$seed" 3 6 15 300 15000 "$eps"
    done
  done
done
summarize setup4
