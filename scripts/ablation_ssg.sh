#!/usr/bin/env bash
# SSG ablation (paper): lite_gs vs static-subset greedy on ship, Setup 4 protocol with K = 4,
# eps in {0.1, 0.2, 0.25, 0.4}.
SCENES="${SCENES:-ship}"
source "$(dirname "$0")/common.sh"
parse_args "$@"
for eps in 0.1 0.2 0.25 0.4; do
  for scene in $SCENES; do
    for method in lite_gs ssg; do
      for seed in $(seq 0 $((SEEDS - 1))); do
        run_one ablation_ssg "$scene" "$method" "${method}_eps$eps" "$seed" 3 4 15 300 15000 "$eps"
      done
    done
  done
done
summarize ablation_ssg
