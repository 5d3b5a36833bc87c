"""Torch-facing wrappers of the numba kernels: binning, the differentiable rasterizer and the attribute Gram.

Same signatures and results as the torch path in `gaussian_renderer.rasterize` / `fisher_partials` (its twin
in the tests), binned by the same `gaussian_renderer.tiles.tile_ranges`; CPU tensors only (the dispatch in
`gaussian_renderer.compiled` sends CUDA tensors to torch).
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import torch

from gaussian_renderer.compiled import kernels, row_kernels
from gaussian_renderer.settings import RasterSettings
from gaussian_renderer.tiles import BLOCK_PIXELS, NUM_GEOMETRY_ATTRIBUTES, grid_size, tile_ranges
from utils.errors import UserError

_FLOAT_DTYPES = (torch.float32, torch.float64)



@dataclass
class CompiledBins:
    """Per-block depth-sorted Gaussian lists in CSR form, and each Gaussian's reach in pixels.

    The kernels work on blocks of `block` x `block` pixels (whole tiles, `BLOCK_PIXELS` or less) while a Gaussian
    still reaches exactly the pixels of its tile rectangle (`tile_ranges` at `settings.tile_size`): `rects` clips it,
    so the images equal the torch path's at the same tile size whatever the block.
    """

    offsets: np.ndarray  # [B + 1] int64: block b's list is ids[offsets[b]:offsets[b + 1]]
    ids: np.ndarray  # [M] int32 kernel indices, front to back within each block
    blocks_x: int
    block: int  # pixels per block side
    rects: np.ndarray  # [n, 4] int64 inclusive pixel rectangle x0, x1, y0, y1 of each listed Gaussian (kernel index)
    order: torch.Tensor  # [n] int64 Gaussian id of each kernel index: listed Gaussians by first appearance


def _use_torch_threads() -> int:
    """Run numba with the threads torch is given (capped by numba's pool size); returns the count."""
    threads = max(1, min(torch.get_num_threads(), numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(threads)
    return threads


def prepare_inputs(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, colors: torch.Tensor,
                   background: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """Contiguous inputs in one float dtype (that of means2d; float32 or float64, else a UserError naming it).

    The conversions are differentiable, so gradients still reach the caller's tensors.
    """
    if means2d.dtype not in _FLOAT_DTYPES:
        raise UserError(f"the compiled rasterizer needs float32 or float64 inputs, got means2d [N,2] of dtype "
                        f"{means2d.dtype}; convert with .float() or use --raster_backend torch")
    if means2d.device.type != "cpu":
        raise UserError(f"the compiled rasterizer runs on CPU tensors only, got {means2d.device}")
    dtype = means2d.dtype
    return tuple(t.to(dtype).contiguous() for t in (means2d, conics, opacities, colors, background))


def _numpy(t: torch.Tensor) -> np.ndarray:
    return t.detach().contiguous().numpy()


def _float64(t: torch.Tensor) -> np.ndarray:
    return _numpy(t.detach().double())


def bin_gaussians_compiled(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor,
                           radii: torch.Tensor, depths: torch.Tensor, width: int, height: int,
                           settings: RasterSettings) -> CompiledBins:
    """Block lists by a parallel counting sort; within a block, Gaussians keep their (stable) depth order. The
    kernels see the listed Gaussians only, renumbered by first appearance (`kernels.first_appearance_order`): their
    per-Gaussian reads and writes then stay close in memory (garden 1296x840: forward 1.18x, Gram 1.11-1.17x,
    backward 1.15x against the model's own order, whose neighbours are scattered over the image)."""
    tile_size = settings.tile_size
    per_block = max(1, BLOCK_PIXELS // tile_size)  # tiles per block side
    block = per_block * tile_size
    blocks_x, blocks_y = grid_size(width, height, block)
    with torch.no_grad():
        ids = torch.nonzero(radii > 0).squeeze(1)  # [n]
        ids = ids[torch.argsort(depths.detach()[ids], stable=True)]  # depth order, ties by id (as the torch path)
        x0, x1, y0, y1 = tile_ranges(means2d.detach()[ids], conics.detach()[ids], opacities.detach()[ids],
                                     radii[ids], width, height, tile_size, settings.alpha_min)  # [n] each, tiles
        rects = torch.zeros(means2d.shape[0], 4, dtype=torch.int64)  # [N, 4]
        rects[ids] = torch.stack([x0 * tile_size, (x1 + 1) * tile_size - 1, y0 * tile_size,
                                  (y1 + 1) * tile_size - 1], 1)
    threads = _use_torch_threads()
    offsets, lists = kernels.bin_tiles(_numpy(x0 // per_block), _numpy(x1 // per_block), _numpy(y0 // per_block),
                                       _numpy(y1 // per_block), _numpy(ids), blocks_x * blocks_y, blocks_x, threads)
    order, lists = kernels.first_appearance_order(lists, means2d.shape[0])
    order = torch.from_numpy(order)
    return CompiledBins(offsets, lists, blocks_x, block, rects[order].numpy(), order)


def scatter_rows(rows: np.ndarray, bins: CompiledBins, n: int) -> torch.Tensor:
    """Per-Gaussian kernel output [n', K] (kernel indices) as [n, K] in Gaussian ids, zero for unlisted Gaussians."""
    out = torch.zeros(n, rows.shape[1], dtype=torch.float64)
    out[bins.order] = torch.from_numpy(rows)
    return out


def _kernel_args(bins: CompiledBins, means2d, conics, opacities, colors, background, width: int, height: int,
                 settings: RasterSettings) -> tuple:
    """The arguments every kernel starts with: bins and reach rectangles, packed float64 attributes (`kernels`
    module docstring) and colours of the listed Gaussians in kernel order, background, image and block geometry,
    alpha cut-offs."""
    with torch.no_grad():
        o = opacities.detach()[bins.order].double()
        cut = torch.log(settings.alpha_min / o.clamp_min(1e-300)) - 1e-9
        geom = torch.cat([means2d.detach()[bins.order].double(), conics.detach()[bins.order].double(), o[:, None],
                          cut[:, None], torch.zeros_like(o)[:, None]], dim=1)  # [n', 8]
    return (bins.offsets, bins.ids, bins.rects, geom.numpy(), _float64(colors.detach()[bins.order]),
            _float64(background), width, height, bins.block, bins.blocks_x, float(settings.alpha_min),
            float(settings.alpha_max))


def _forward(bins: CompiledBins, means2d, conics, opacities, colors, background, width: int, height: int,
             settings: RasterSettings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`row_kernels.forward`: image [D, H, W], final transmittance [H, W] (float64), last [H, W] (int32)."""
    image = np.zeros((colors.shape[1], height, width))
    trans = np.ones((height, width))
    last = np.zeros((height, width), np.int32)
    row_kernels.forward(*_kernel_args(bins, means2d, conics, opacities, colors, background, width, height,
                                      settings), float(settings.transmittance_min), image, trans, last,
                        _use_torch_threads())
    return image, trans, last


def composite_compiled(bins: CompiledBins, means2d, conics, opacities, colors, background, width: int, height: int,
                       settings: RasterSettings) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Forward pass: image [D, H, W] (input dtype), final transmittance [H, W] (float64), last [H, W] (int32)."""
    image, trans, last = _forward(bins, means2d, conics, opacities, colors, background, width, height, settings)
    return torch.from_numpy(image).to(colors.dtype), torch.from_numpy(trans), torch.from_numpy(last)


def transmittance_compiled(bins: CompiledBins, means2d, conics, opacities, width: int, height: int,
                           settings: RasterSettings) -> tuple[np.ndarray, np.ndarray]:
    """The forward pass without colours (what a replay needs): final transmittance [H, W] (float64), last [H, W]
    (int32), equal to `composite_compiled`'s, ~1.3x faster (no colour accumulation)."""
    no_colors = means2d.new_zeros(means2d.shape[0], 0)  # [N, 0]
    _, trans, last = _forward(bins, means2d, conics, opacities, no_colors, means2d.new_zeros(0), width, height,
                              settings)
    return trans, last


class _RasterizeCompiled(torch.autograd.Function):
    """Forward and backward by the numba kernels; nothing per pair is stored."""

    @staticmethod
    def forward(ctx, means2d, conics, opacities, colors, background, bins, width, height, settings):
        image, trans, last = composite_compiled(bins, means2d, conics, opacities, colors, background, width,
                                                height, settings)
        ctx.save_for_backward(means2d, conics, opacities, colors, background)
        ctx.state = (bins, width, height, settings, trans, last)
        return image, (1 - trans).to(means2d.dtype)

    @staticmethod
    def backward(ctx, grad_image, grad_alpha):
        means2d, conics, opacities, colors, background = ctx.saved_tensors
        bins, width, height, settings, trans, last = ctx.state
        g_img, g_alpha = grad_image.double(), grad_alpha.double()  # [D, H, W], [H, W] (materialised by autograd)
        out = row_kernels.backward(*_kernel_args(bins, means2d, conics, opacities, colors, background, width, height,
                                             settings), trans.numpy(), last.numpy(), _float64(g_img), _float64(g_alpha),
                               _use_torch_threads())
        grad = scatter_rows(out, bins, means2d.shape[0]).to(means2d.dtype)  # [N, 6 + D]
        grad_bg = (g_img * trans).sum((1, 2)).to(background.dtype)
        geo = NUM_GEOMETRY_ATTRIBUTES
        return (grad[:, 0:2], grad[:, 2:5], grad[:, 5], grad[:, geo:], grad_bg, None, None, None, None)


def rasterize_compiled(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, colors: torch.Tensor,
                       depths: torch.Tensor, radii: torch.Tensor, width: int, height: int, background: torch.Tensor,
                       settings: RasterSettings) -> tuple[torch.Tensor, torch.Tensor]:
    """`gaussian_renderer.rasterize.rasterize` by the compiled kernels: image [D, H, W], alpha [H, W]."""
    means2d, conics, opacities, colors, background = prepare_inputs(means2d, conics, opacities, colors, background)
    bins = bin_gaussians_compiled(means2d, conics, opacities, radii, depths, width, height, settings)
    return _RasterizeCompiled.apply(means2d, conics, opacities, colors, background, bins, width, height, settings)


@torch.no_grad()
def attribute_gram_compiled(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor,
                            colors: torch.Tensor, depths: torch.Tensor, radii: torch.Tensor, width: int, height: int,
                            background: torch.Tensor, settings: RasterSettings,
                            weights: torch.Tensor | None = None,
                            seen_only: bool = False) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """`gaussian_renderer.fisher_partials.attribute_gram` by the compiled kernels: float64 [N, A, A]; with
    `seen_only`, `seen_attribute_gram`'s (indices [n], Grams [n, A, A]) of the Gaussians with non-zero moment sums."""
    means2d, conics, opacities, colors, background = prepare_inputs(means2d, conics, opacities, colors, background)
    d = colors.shape[1]
    bins = bin_gaussians_compiled(means2d, conics, opacities, radii, depths, width, height, settings)
    trans, last = transmittance_compiled(bins, means2d, conics, opacities, width, height, settings)
    pixel_weights = np.ones((height, width)) if weights is None else _float64(weights)
    args = _kernel_args(bins, means2d, conics, opacities, colors, background, width, height, settings)
    sums = row_kernels.gram(*args, trans, last, pixel_weights, _use_torch_threads())  # [n', 15 + 6 D + 1], kernel idx
    geom = args[3]  # [n', 8] packed attributes in kernel order: conic a, b, c in columns 2-4, opacity in 5
    conics_k, opacities_k = np.ascontiguousarray(geom[:, 2:5]), np.ascontiguousarray(geom[:, 5])
    if not seen_only:
        gram = kernels.assemble_gram(sums, conics_k, opacities_k, d, np.arange(sums.shape[0], dtype=np.int64))
        a = NUM_GEOMETRY_ATTRIBUTES + d
        full = torch.zeros(means2d.shape[0], a, a, dtype=torch.float64)  # [N, A, A]
        full[bins.order] = torch.from_numpy(gram)
        return full
    rows = kernels.nonzero_rows(sums)  # kernel indices; in ascending Gaussian ids:
    ids = bins.order[torch.from_numpy(rows)]
    ids, by_id = torch.sort(ids)
    rows = rows[by_id.numpy()]
    return ids, torch.from_numpy(kernels.assemble_gram(sums, conics_k, opacities_k, d, rows))


# raw parameter groups and their widths in the Jacobian's columns (sh_rest: 3 (K - 1)), as `projection_kernels`
_JACOBIAN_GROUPS = ("means", "quats", "log_scales", "logit_opacities", "sh_dc", "sh_rest")


@torch.no_grad()
def projection_jacobian_compiled(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor,
                                 logit_opacities: torch.Tensor, sh_coeffs: torch.Tensor, sh_degree: int,
                                 viewmat: torch.Tensor, intrinsics: torch.Tensor, width: int, height: int,
                                 param_groups: tuple[str, ...], near_plane: float = 0.01,
                                 dilation: float = 0.3) -> torch.Tensor:
    """`projection_partials.projection_jacobian_closed_form` by the numba kernel, its columns concatenated in
    `param_groups` order: float64 [N, 9, P] (the kernel computes in float64 whatever the input dtype)."""
    from gaussian_renderer.compiled import projection_kernels
    from gaussian_renderer.projection import camera_center, frustum_limits

    k_all = sh_coeffs.shape[1]
    widths = {"means": 3, "quats": 4, "log_scales": 3, "logit_opacities": 1, "sh_dc": 3, "sh_rest": 3 * (k_all - 1)}
    cols, total = np.full(len(_JACOBIAN_GROUPS), -1, np.int64), 0
    for group in param_groups:
        cols[_JACOBIAN_GROUPS.index(group)] = total
        total += widths[group]
    view = viewmat.detach().double()
    intr = intrinsics.detach().double()
    (neg_x, pos_x), (neg_y, pos_y) = frustum_limits(*intr.unbind(-1), width, height)
    limits = torch.stack([neg_x, pos_x, neg_y, pos_y])
    out = np.empty((means.shape[0], 9, total))  # the kernel zeroes each row in the thread that fills it
    dtype = torch.float64 if means.dtype == torch.float64 else torch.float32  # the kernel reads either as float64
    inputs = [_numpy(t.detach().to(dtype)) for t in (means, quats, log_scales, logit_opacities, sh_coeffs)]
    projection_kernels.projection_jacobian_kernel(
        *inputs, sh_degree, _numpy(view[:3, :3]), _numpy(view[:3, 3]), _float64(camera_center(view)), _numpy(intr),
        _numpy(limits), float(near_plane), float(dilation), cols, out, _use_torch_threads())
    return torch.from_numpy(out)


@torch.no_grad()
def project_and_shade_compiled(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor,
                               sh_dc: torch.Tensor, sh_rest: torch.Tensor, sh_degree: int, viewmat: torch.Tensor,
                               intrinsics: torch.Tensor, width: int, height: int, near_plane: float = 0.01,
                               dilation: float = 0.3) -> tuple[Projection, torch.Tensor]:
    """`projection.project_gaussians` of the raw parameters (quaternions normalised, scales exponentiated inside) and
    `sh.sh_to_colors` of the Gaussians it keeps, by one numba kernel, float64, no gradients: (Projection, colours
    [N, 3], 0 where culled). The torch functions are its twin (tests/test_projection_partials.py)."""
    from gaussian_renderer.compiled import projection_kernels
    from gaussian_renderer.projection import Projection, camera_center, frustum_limits

    n = means.shape[0]
    view, intr = viewmat.detach().double(), intrinsics.detach().double()
    (neg_x, pos_x), (neg_y, pos_y) = frustum_limits(*intr.unbind(-1), width, height)
    out = {"means2d": np.empty((n, 2)), "conics": np.empty((n, 3)), "depths": np.empty(n),
           "radii": np.empty(n, np.int64)}
    colors = np.empty((n, 3))
    projection_kernels.project_and_shade_kernel(
        *(_numpy(t.detach()) for t in (means, quats, log_scales, sh_dc, sh_rest)), sh_degree, _numpy(view[:3, :3]),
        _numpy(view[:3, 3]), _float64(camera_center(view)), _numpy(intr),
        _numpy(torch.stack([neg_x, pos_x, neg_y, pos_y])), float(near_plane), float(dilation), width, height,
        out["means2d"], out["conics"], out["depths"], out["radii"], colors, _use_torch_threads())
    return Projection(**{k: torch.from_numpy(v) for k, v in out.items()}), torch.from_numpy(colors)
