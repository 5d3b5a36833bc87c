#!/usr/bin/env bash
# Setup 3 (paper): 3 seed views, +4 per step to 15 views, 100 v iterations per stage, 11,000 in total
# (Mip-NeRF 360).
DEFAULT_SCENES=garden
source "$(dirname "$0")/common.sh"
parse_args "$@"
run_setup setup3 3 4 15 100 11000
finish setup3
