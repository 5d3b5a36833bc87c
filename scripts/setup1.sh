#!/usr/bin/env bash
# Setup 1 (paper): 2 seed views, +3 per step to 11 views, 100 v iterations per stage, 11,000 in total
# (Blender and Mip-NeRF 360).
DEFAULT_SCENES=lego
source "$(dirname "$0")/common.sh"
parse_args "$@"
run_setup setup1 2 3 11 100 11000
finish setup1
