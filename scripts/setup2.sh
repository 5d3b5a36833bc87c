#!/usr/bin/env bash
# Setup 2 (paper): 5 seed views, +4 per step to 21 views, 300 v iterations per stage, 21,000 in total (Blender).
# Protocol: experiments/protocols.py; options: python scripts/grid.py --help.
source "$(dirname "$0")/common.sh"
run_grid setup2 "$@"
