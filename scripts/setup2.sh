#!/usr/bin/env bash
# Setup 2 (paper): 5 seed views, +4 per step to 21 views, 300 v iterations per stage, 21,000 in total (Blender).
DEFAULT_SCENES=lego
source "$(dirname "$0")/common.sh"
parse_args "$@"
run_setup setup2 5 4 21 300 21000
finish setup2
