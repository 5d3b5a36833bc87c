"""One figure for a rendered test view: ground truth | render | absolute error | uncertainty (render.py --uncertainty).

    python scripts/uncertainty_figure.py output/lego --view 3 --out docs/results/uncertainty_lego/view03.png

Reads MODEL/test/ours_N/{gt,renders,uncertainty/KIND} (the largest N unless --iteration; --kind, default
position_variance) and per_view.json's whole-image Spearman and AUSE_RMSE of that kind for the title when metrics.py
has run.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from utils.errors import UserError, run_cli  # noqa: E402
from utils.io import read_json  # noqa: E402
from utils.metrics_core import UNCERTAINTY_KINDS, method_dirs, read_rgb, uncertainty_key  # noqa: E402
from utils.model_dir import PER_VIEW, method_name  # noqa: E402


def make_figure(model: Path, view: int, out: Path, iteration: int | None = None,
                kind: str = "position_variance") -> Path:
    """Write the four-panel PNG of test view `view` to `out`; returns `out`."""
    dirs = method_dirs(model)
    if iteration is not None:
        dirs = [d for d in dirs if d.name == method_name(iteration)]
    if not dirs:
        raise UserError(f"{model}: no test/ours_N renders{'' if iteration is None else f' for {iteration}'}; "
                        "run render.py --uncertainty first")
    method_dir, name = dirs[-1], f"{view:05d}"
    if kind not in UNCERTAINTY_KINDS:
        raise UserError(f"unknown uncertainty kind {kind!r}; valid: {', '.join(UNCERTAINTY_KINDS)}")
    if not (method_dir / "uncertainty" / kind / f"{name}.npy").is_file():
        raise UserError(f"{method_dir}: no uncertainty/{kind}/{name}.npy; run render.py -m {model} --uncertainty")
    gt = read_rgb(method_dir / "gt" / f"{name}.png").permute(1, 2, 0).numpy()  # [H, W, 3]
    image = read_rgb(method_dir / "renders" / f"{name}.png").permute(1, 2, 0).numpy()
    error = np.abs(image - gt).mean(-1)  # [H, W]
    uncertainty = np.load(method_dir / "uncertainty" / kind / f"{name}.npy")  # [H, W]
    positive = uncertainty[uncertainty > 0]
    lo = positive.min() if positive.size else 1e-12
    fig, axes = plt.subplots(1, 4, figsize=(12, 3.4), dpi=110)
    axes[0].imshow(gt)
    axes[1].imshow(image)
    err = axes[2].imshow(error, cmap="magma", vmin=0)
    unc = axes[3].imshow(np.maximum(uncertainty, lo), cmap="inferno",
                         norm=matplotlib.colors.LogNorm(vmin=lo, vmax=max(uncertainty.max(), lo * 10)))
    fig.colorbar(err, ax=axes[2], fraction=0.046, pad=0.02)
    fig.colorbar(unc, ax=axes[3], fraction=0.046, pad=0.02)
    titles = ["test view (ground truth)", "render", "|error| (mean RGB)", f"uncertainty ({kind})"]
    for ax, title in zip(axes, titles):
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    scores = (read_json(model / PER_VIEW, missing="none") or {}).get(method_dir.name)
    if scores is not None:
        rho, area = (scores.get(uncertainty_key(m, kind, "image"), {}).get(name + ".png")
                     for m in ("Spearman", "AUSE_RMSE"))
        if rho is not None and area is not None:
            fig.suptitle(f"{model.name} {method_dir.name} view {view}: {kind}, image Spearman {rho:.3f}, "
                         f"AUSE_RMSE {area:.4f}", fontsize=10)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("model", type=Path, help="model directory rendered with render.py --uncertainty")
    parser.add_argument("--view", type=int, default=0, help="test view index (default 0)")
    parser.add_argument("--iteration", type=int, default=None, help="ours_N to use (default: the largest N)")
    parser.add_argument("--kind", default="position_variance",
                        help=f"uncertainty map kind: {', '.join(UNCERTAINTY_KINDS)} (default position_variance)")
    parser.add_argument("--out", type=Path, required=True, help="output PNG")
    args = parser.parse_args()
    print(make_figure(args.model, args.view, args.out, args.iteration, args.kind))


if __name__ == "__main__":
    run_cli(main)
