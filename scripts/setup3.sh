#!/usr/bin/env bash
# Setup 3 (paper): 3 seed views, +4 per step to 15 views, 100 v iterations per stage, 11,000 in total
# (Mip-NeRF 360).
# Protocol: experiments/protocols.py; options: python scripts/grid.py --help.
source "$(dirname "$0")/common.sh"
run_grid setup3 "$@"
