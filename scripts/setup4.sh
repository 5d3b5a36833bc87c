#!/usr/bin/env bash
# Setup 4 (paper): 3 seed views, K in {3, 4, 6} to 15 views, 300 v iterations per stage, 15,000 in total
# (Blender ship); every method at each K with --eps (paper: 0.1), and for K = 6 also the eps-taking methods
# (lite_gs) at eps 0.3 and 0.6.
# Protocol: experiments/protocols.py; options: python scripts/grid.py --help.
source "$(dirname "$0")/common.sh"
run_grid setup4 "$@"
