"""One figure for a rendered test view: ground truth | render | absolute error | uncertainty (render.py --uncertainty).

    python scripts/uncertainty_figure.py output/lego --view 3 --out docs/results/uncertainty_lego/view03.png

Reads MODEL/test/ours_N/{gt,renders,uncertainty} (the largest N unless --iteration) and per_view.json's Spearman
and AUSE for the title when metrics.py has run.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from utils.errors import UserError, run_cli  # noqa: E402
from utils.metrics_core import method_dirs, read_rgb  # noqa: E402
from utils.model_dir import PER_VIEW, method_name  # noqa: E402


def make_figure(model: Path, view: int, out: Path, iteration: int | None = None) -> Path:
    """Write the four-panel PNG of test view `view` to `out`; returns `out`."""
    dirs = method_dirs(model)
    if iteration is not None:
        dirs = [d for d in dirs if d.name == method_name(iteration)]
    if not dirs:
        raise UserError(f"{model}: no test/ours_N renders{'' if iteration is None else f' for {iteration}'}; "
                        "run render.py --uncertainty first")
    method_dir, name = dirs[-1], f"{view:05d}"
    if not (method_dir / "uncertainty" / f"{name}.npy").is_file():
        raise UserError(f"{method_dir}: no uncertainty/{name}.npy; run render.py -m {model} --uncertainty")
    gt = read_rgb(method_dir / "gt" / f"{name}.png").permute(1, 2, 0).numpy()  # [H, W, 3]
    image = read_rgb(method_dir / "renders" / f"{name}.png").permute(1, 2, 0).numpy()
    error = np.abs(image - gt).mean(-1)  # [H, W]
    uncertainty = np.load(method_dir / "uncertainty" / f"{name}.npy")  # [H, W]
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
    titles = ["test view (ground truth)", "render", "|error| (mean RGB)", "uncertainty (positional var.)"]
    for ax, title in zip(axes, titles):
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    per_view = model / PER_VIEW
    if per_view.is_file():
        scores = json.loads(per_view.read_text()).get(method_dir.name, {})
        if "Spearman" in scores:
            fig.suptitle(f"{model.name} {method_dir.name} view {view}: Spearman "
                         f"{scores['Spearman'][name + '.png']:.3f}, AUSE {scores['AUSE'][name + '.png']:.4f}",
                         fontsize=10)
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
    parser.add_argument("--out", type=Path, required=True, help="output PNG")
    args = parser.parse_args()
    print(make_figure(args.model, args.view, args.out, args.iteration))


if __name__ == "__main__":
    run_cli(main)
