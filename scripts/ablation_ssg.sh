#!/usr/bin/env bash
# SSG ablation (paper): lite_gs (resamples its candidate subset every pick) vs static-subset greedy (one subset
# per stage) on Blender ship, Setup 4 protocol with K = 4, eps in {0.1, 0.2, 0.25, 0.4, 0.6}. --eps is not used.
# Protocol: experiments/protocols.py; options: python scripts/grid.py --help.
source "$(dirname "$0")/common.sh"
run_grid ablation_ssg "$@"
