#!/usr/bin/env bash
# Setup 1 (paper): 2 seed views, +3 per step to 11 views, 100 v iterations per stage, 11,000 in total
# (Blender and Mip-NeRF 360).
# Protocol: experiments/protocols.py; options: python scripts/grid.py --help.
source "$(dirname "$0")/common.sh"
run_grid setup1 "$@"
