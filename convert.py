"""Recover camera poses of a folder of photographs with COLMAP (CPU), as graphdeco's 3DGS `convert.py` does.

    python convert.py -s DATA            # photographs in DATA/input (or DATA/images, moved to DATA/input)
    python -m train -s DATA -m output/x --eval -i images_4

Writes DATA/sparse/0 (undistorted PINHOLE model), DATA/images (undistorted) and DATA/images_2, _4, _8, and
DATA/convert.json (steps, seconds, counts); prints the registered-image count and the mean reprojection error.
Matching: exhaustive up to 60 images, sequential (overlap 10, no loop detection) above; --matcher overrides.
COLMAP must be on PATH (bash scripts/install_colmap.sh installs the Debian package).
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from scene.colmap_convert import CAMERA_MODELS, EXHAUSTIVE_MAX_IMAGES, ConvertOptions, convert
from utils.errors import run_cli


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-s", "--source_path", required=True, help="dataset folder holding input/ or images/")
    p.add_argument("--matcher", default="auto", choices=("auto", "exhaustive", "sequential"),
                   help=f"auto: exhaustive up to {EXHAUSTIVE_MAX_IMAGES} images, else sequential (default auto)")
    p.add_argument("--overlap", type=int, default=10,
                   help="sequential matching: following images each image is matched with (default 10)")
    p.add_argument("--camera_model", default="SIMPLE_RADIAL", choices=CAMERA_MODELS,
                   help="one camera shared by all images (default SIMPLE_RADIAL)")
    p.add_argument("--max_image_size", type=int, default=0,
                   help="feature extraction on images downscaled to at most this many px (0: COLMAP's 3200)")
    p.add_argument("--max_num_features", type=int, default=8192, help="SIFT features per image (default 8192)")
    p.add_argument("--threads", type=int, default=-1, help="COLMAP threads (-1: all cores; default -1)")
    p.add_argument("--allow_partial", action="store_true",
                   help="continue with the registered images when COLMAP cannot register all")
    p.add_argument("--colmap_executable", default="colmap", help="COLMAP executable (default: colmap on PATH)")
    return p


def main() -> int:
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stdout)
    args = build_parser().parse_args()
    opts = ConvertOptions(matcher=args.matcher, overlap=args.overlap, camera_model=args.camera_model,
                          max_image_size=args.max_image_size, max_num_features=args.max_num_features,
                          threads=args.threads, allow_partial=args.allow_partial, colmap=args.colmap_executable)
    data = Path(args.source_path)
    res = convert(data, opts)
    steps = ", ".join(f"{s.name.split(' ', 1)[-1]} {s.seconds:.0f} s" for s in res.steps)
    print(f"convert: registered {res.num_registered} of {res.num_input} images, mean reprojection error "
          f"{res.mean_reprojection_error:.3f} px, {res.num_points} points; {res.seconds:.0f} s ({steps})")
    print(f"convert: wrote {data / 'sparse' / '0'}, {data / 'images'}, images_2/4/8, {data / 'convert.json'}")
    return 0


if __name__ == "__main__":
    run_cli(main)
