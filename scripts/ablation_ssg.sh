#!/usr/bin/env bash
# SSG ablation (paper): lite_gs (resamples its candidate subset every pick) vs static-subset greedy (one subset
# per stage) on Blender ship, Setup 4 protocol with K = 4, eps in {0.1, 0.2, 0.25, 0.4}. --eps is not used.
DEFAULT_SCENES=ship
DEFAULT_METHODS="lite_gs ssg"
source "$(dirname "$0")/common.sh"
parse_args "$@"
for eps in 0.1 0.2 0.25 0.4; do
  for scene in $SCENES; do
    for method in $METHODS; do
      for seed in $(seq 0 $((SEEDS - 1))); do
        run_one ablation_ssg "$scene" "$method" "$(tag_for "$method" 4 "$eps" no always)" "$seed" 3 4 15 300 15000 "$eps"
      done
    done
  done
done
finish ablation_ssg
