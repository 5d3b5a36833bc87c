"""Fisher-only partials: what the information oracle needs beyond the image (no autograd through pixels).

A pixel depends on Gaussian i only through its 2D attributes a_i = (mean x, y, conic a, b, c, opacity, colour[D]),
so a view's per-Gaussian Fisher block is J_proj,i^T G_i J_proj,i with
* `attribute_gram` -> G [N, A, A]: sum over pixels and channels of (dC/da_i)(dC/da_i)^T, by the rasterizer's
  closed-form per-pair replay;
* `projection_jacobian` -> J_proj [N, A, P]: d a_i / d (raw parameters of Gaussian i);
* `project_and_shade`: the render inputs of a view (projection, kept Gaussians, their colours) without gradients;
* `pixel_attribute_partials`: the packed per-pair Jacobians themselves (small images; tests and inspection).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from gaussian_renderer.compiled import use_compiled
from gaussian_renderer.projection import Projection, camera_center, project_gaussians
from gaussian_renderer.projection_partials import projection_jacobian_closed_form
from gaussian_renderer.settings import RasterSettings
from gaussian_renderer.sh import num_sh_bases, sh_to_colors
from gaussian_renderer.tiles import (NUM_GEOMETRY_ATTRIBUTES, alpha_partials, bin_gaussians, check_inputs,
                                     color_alpha_partials, composite, from_image, iterate_chunks, scatter_rows)
from utils.errors import UserError


@torch.no_grad()
def attribute_gram(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, colors: torch.Tensor,
                   depths: torch.Tensor, radii: torch.Tensor, width: int, height: int, background: torch.Tensor,
                   settings: RasterSettings | None = None, weights: torch.Tensor | None = None) -> torch.Tensor:
    """Per-Gaussian Gram matrix of the pixel-colour partials w.r.t. the 2D attributes.

    G_i = sum_pixels weight_p sum_channels (dC_pc / da_i)(dC_pc / da_i)^T, a_i = (mean x, y, conic a, b, c, opacity, colour).
    Per pair the Jacobian is [u v^T | w I] with u = dC/dalpha [D], v = dalpha/d(geometry) [6], w = alpha T, so the
    Gram is [[|u|^2 v v^T, w v u^T], [w u v^T, w^2 I]]. One forward pass gives the final colours (u needs them),
    then a replay sums these blocks over each tile's pixels with one small matrix product per (tile, Gaussian), in
    the input dtype, before a float64 scatter per Gaussian. Memory stays at one chunk's pairs.

    Args:
        weights: optional per-pixel weights (e.g. inverse noise variances or a mask), 1 when None. [H, W]
    Returns:
        float64 Gram matrices. [N, A, A], A = 6 + D
    """
    settings = settings or RasterSettings()
    check_inputs(means2d, conics, opacities, colors, depths, radii, background)
    assert weights is None or weights.shape == (height, width), f"weights must be [H,W], got {tuple(weights.shape)}"
    if use_compiled(settings.backend, means2d):
        from gaussian_renderer.compiled.ops import attribute_gram_compiled
        return attribute_gram_compiled(means2d, conics, opacities, colors, depths, radii, width, height, background,
                                       settings, weights)
    n, d = colors.shape
    geo = NUM_GEOMETRY_ATTRIBUTES
    bins = bin_gaussians(means2d, conics, opacities, radii, depths, width, height, settings)
    pixel_weights = None if weights is None else from_image(weights[None].to(means2d.dtype), bins)[..., 0]  # [T, P]
    final_color = composite(bins, means2d, conics, opacities, colors, background, settings)[0].transpose(1, 2)
    final_color = final_color.contiguous()  # [T, D, P]
    prefix = torch.zeros_like(final_color)
    # Per Gaussian: [v (|u|^2 v)^T | v (w u)^T] (6 x (6 + D)) and sum w^2, accumulated in float64 across tiles.
    sums = torch.zeros(n, geo * (geo + d) + 1, dtype=torch.float64, device=means2d.device)
    for chunk in iterate_chunks(bins, means2d, conics, opacities, settings):
        u = color_alpha_partials(chunk, colors, final_color, prefix)  # [Ta, c, D, P]
        v = alpha_partials(chunk, conics, dim=2)  # [Ta, c, 6, P]
        t, c, _, p = v.shape
        uu, w = (u * u).sum(2, keepdim=True), chunk.weight[:, :, None, :]  # [Ta, c, 1, P] each
        ww = w * w
        if pixel_weights is not None:
            wp = pixel_weights[chunk.tiles][:, None, None, :]  # [Ta, 1, 1, P]
            uu, ww = uu * wp, ww * wp
            w = w * wp
        right = torch.cat([uu * v, w * u], dim=2)  # [Ta, c, 6 + D, P]
        prod = torch.bmm(v.reshape(t * c, geo, p), right.reshape(t * c, geo + d, p).transpose(1, 2))
        ww = ww.sum((2, 3)).reshape(t * c, 1)
        rows = torch.cat([prod.reshape(t * c, -1), ww], dim=1).double()
        sums += scatter_rows(rows.reshape(t, c, -1), chunk.ids, n)
    prod = sums[:, :-1].reshape(n, geo, geo + d)
    gram = torch.zeros(n, geo + d, geo + d, dtype=torch.float64, device=means2d.device)
    gram[:, :geo, :] = prod
    gram[:, :geo, :geo] = 0.5 * (prod[:, :, :geo] + prod[:, :, :geo].transpose(1, 2))  # exactly symmetric
    gram[:, geo:, :geo] = prod[:, :, geo:].transpose(1, 2)
    gram[:, geo:, geo:] = sums[:, -1, None, None] * torch.eye(d, dtype=torch.float64, device=means2d.device)
    return gram


@torch.no_grad()
def project_and_shade(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor, sh_dc: torch.Tensor,
                      sh_rest: torch.Tensor, sh_degree: int, viewmat: torch.Tensor, intrinsics: torch.Tensor,
                      width: int, height: int,
                      settings: RasterSettings | None = None) -> tuple[Projection, torch.Tensor, torch.Tensor]:
    """A view's render inputs for the Fisher pass, from the raw parameters (wxyz quaternions of any norm, log-scales,
    SH bands [N, 1, 3] and [N, K - 1, 3]): the projection, the ids [n] of the Gaussians it keeps (radius > 0) and
    their colours [n, 3]. The compiled backend runs one numba kernel in float64
    (`compiled.ops.project_and_shade_compiled`); the torch path, its twin, `project_gaussians` and `sh_to_colors`."""
    settings = settings or RasterSettings()
    if use_compiled(settings.backend, means):
        from gaussian_renderer.compiled.ops import project_and_shade_compiled
        proj, colors = project_and_shade_compiled(means, quats, log_scales, sh_dc, sh_rest, sh_degree, viewmat,
                                                  intrinsics, width, height)
        ids = torch.nonzero(proj.radii > 0).squeeze(1)
        return proj, ids, colors[ids]
    proj = project_gaussians(means, quats / quats.norm(dim=-1, keepdim=True), torch.exp(log_scales), viewmat,
                             intrinsics, width, height)
    ids = torch.nonzero(proj.radii > 0).squeeze(1)
    sh = torch.cat([sh_dc[ids], sh_rest[ids]], dim=1)  # [n, K, 3]
    return proj, ids, sh_to_colors(sh, means[ids], camera_center(viewmat), sh_degree)


@torch.no_grad()
def seen_attribute_gram(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, colors: torch.Tensor,
                        depths: torch.Tensor, radii: torch.Tensor, width: int, height: int, background: torch.Tensor,
                        settings: RasterSettings | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """`attribute_gram` of the Gaussians the view sees only (those with a non-zero Gram), without forming the others.

    The compiled backend assembles just those rows from its moment sums; the torch backend selects them from the
    full [N, A, A] result (the obviously correct twin).

    Returns:
        indices of the seen Gaussians, ascending [n]; their float64 Grams [n, A, A]
    """
    settings = settings or RasterSettings()
    if use_compiled(settings.backend, means2d):
        check_inputs(means2d, conics, opacities, colors, depths, radii, background)
        from gaussian_renderer.compiled.ops import attribute_gram_compiled
        return attribute_gram_compiled(means2d, conics, opacities, colors, depths, radii, width, height, background,
                                       settings, seen_only=True)
    gram = attribute_gram(means2d, conics, opacities, colors, depths, radii, width, height, background, settings)
    indices = torch.nonzero((gram != 0).flatten(1).any(dim=1)).flatten() if gram.shape[0] else \
        torch.zeros(0, dtype=torch.long, device=gram.device)
    return indices, gram[indices]


@dataclass
class PairPartials:
    """Packed per-(pixel, Gaussian) Jacobians of the pixel colour w.r.t. the Gaussian's 2D attributes."""

    pixel_ids: torch.Tensor  # [M] flat pixel index y * W + x
    gaussian_ids: torch.Tensor  # [M]
    jac: torch.Tensor  # [M, D, A]


@torch.no_grad()
def pixel_attribute_partials(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor,
                             colors: torch.Tensor, depths: torch.Tensor, radii: torch.Tensor, width: int,
                             height: int, background: torch.Tensor,
                             settings: RasterSettings | None = None) -> PairPartials:
    """Closed-form d colour / d 2D attributes for every contributing pair (no autograd). Small images only.

    A pair contributes when its alpha survives the cut-offs (alpha_min, power <= 0, early stop); clamped pairs
    keep their colour and background terms but have zero alpha derivative.
    """
    settings = settings or RasterSettings()
    check_inputs(means2d, conics, opacities, colors, depths, radii, background)
    d = colors.shape[1]
    bins = bin_gaussians(means2d, conics, opacities, radii, depths, width, height, settings)
    final_color = composite(bins, means2d, conics, opacities, colors, background, settings)[0].transpose(1, 2)
    final_color = final_color.contiguous()  # [T, D, P]
    prefix = torch.zeros_like(final_color)
    pix, gid, jacs = [], [], []
    eye = torch.eye(d, dtype=means2d.dtype, device=means2d.device)
    for chunk in iterate_chunks(bins, means2d, conics, opacities, settings):
        u = color_alpha_partials(chunk, colors, final_color, prefix).transpose(2, 3)  # [Ta, c, P, D]
        v = alpha_partials(chunk, conics)  # [Ta, c, P, 6]
        jac = torch.cat([u[..., :, None] * v[..., None, :],
                         chunk.weight[..., None, None] * eye], dim=-1)  # [Ta, c, P, D, A]
        mask = chunk.alpha > 0
        t_idx, c_idx, p_idx = torch.nonzero(mask, as_tuple=True)
        pix.append(bins.pixel_index[chunk.tiles[t_idx], p_idx])
        gid.append(chunk.ids[t_idx, c_idx])
        jacs.append(jac[mask])
    if not jacs:
        empty = torch.zeros(0, dtype=torch.long, device=means2d.device)
        return PairPartials(empty, empty, means2d.new_zeros(0, d, NUM_GEOMETRY_ATTRIBUTES + d))
    return PairPartials(torch.cat(pix), torch.cat(gid), torch.cat(jacs))


RAW_PARAMETER_GROUPS = ("means", "quats", "log_scales", "logit_opacities", "sh_dc", "sh_rest")  # raw parameters, in order


def projection_jacobian(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor,
                        logit_opacities: torch.Tensor, sh_coeffs: torch.Tensor, sh_degree: int,
                        viewmat: torch.Tensor, intrinsics: torch.Tensor, width: int, height: int,
                        param_groups: tuple[str, ...] = ("means", "quats", "log_scales", "logit_opacities", "sh_dc"),
                        backend: str = "torch") -> torch.Tensor:
    """Jacobian of each Gaussian's 2D attributes w.r.t. its own raw parameters, in closed form.

    2D attributes (A = 9): mean2d x, y, conic a, b, c, opacity, colour RGB. Raw parameters, in `param_groups`
    order: means (3), quats (4, unnormalised), log_scales (3), logit_opacities (1), sh_dc (3), and with "sh_rest"
    the remaining SH coefficients (3 (K-1)). Forward-mode formulas (`projection_partials`), one batched pass; the
    twin `projection_jacobian_autograd` gives the same by A backward passes. Where the colour clamp max(., 0) is
    active the colour rows are 0. Rows of culled Gaussians are finite but meaningless (no pixels).

    Args:
        means: [N, 3]; quats: raw wxyz [N, 4]; log_scales: [N, 3]; logit_opacities: [N]; sh_coeffs: [N, K, 3]
        sh_degree: active SH degree for the colour; viewmat [4, 4], intrinsics [4], width, height: the camera.
        param_groups: which raw parameters form the columns, a subsequence of
            ("means", "quats", "log_scales", "logit_opacities", "sh_dc", "sh_rest") in any order.
        backend: a rasterizer backend (`RasterSettings.backend`): "torch" = the batched torch formulas
            (`projection_partials`), "compiled"/"auto" = the numba kernel (`compiled.projection_kernels`) on CPU
            tensors, which computes in float64.
    Returns:
        J, in the dtype of `means` (torch) or float64 (compiled). [N, A, P]
    """
    _check_jacobian_inputs(means, log_scales, logit_opacities, sh_coeffs, sh_degree, param_groups)
    if use_compiled(backend, means):
        from gaussian_renderer.compiled.ops import projection_jacobian_compiled
        return projection_jacobian_compiled(means, quats, log_scales, logit_opacities, sh_coeffs, sh_degree, viewmat,
                                            intrinsics, width, height, param_groups)
    blocks = projection_jacobian_closed_form(means, quats, log_scales, logit_opacities, sh_coeffs, sh_degree, viewmat,
                                             intrinsics, width, height, param_groups)
    return torch.cat([blocks[g] for g in param_groups], dim=2)


def _check_jacobian_inputs(means, log_scales, logit_opacities, sh_coeffs, sh_degree, param_groups) -> None:
    bad = [g for g in param_groups if g not in RAW_PARAMETER_GROUPS]
    if bad or len(set(param_groups)) != len(param_groups) or not param_groups:
        raise UserError(f"Fisher parameter groups {tuple(param_groups)} are invalid; choose distinct names from "
                        f"{', '.join(RAW_PARAMETER_GROUPS)}")
    n = means.shape[0]
    assert sh_coeffs.ndim == 3 and sh_coeffs.shape[0] == n and sh_coeffs.shape[1] >= num_sh_bases(sh_degree), \
        f"sh_coeffs must be [N,K,3] with N = {n}, K >= {num_sh_bases(sh_degree)}, got {tuple(sh_coeffs.shape)}"
    assert logit_opacities.shape == (n,), f"logit_opacities must be [N], got {tuple(logit_opacities.shape)}"
    assert log_scales.shape == (n, 3), f"log_scales must be [N,3], got {tuple(log_scales.shape)}"


def projection_jacobian_autograd(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor,
                                 logit_opacities: torch.Tensor, sh_coeffs: torch.Tensor, sh_degree: int,
                                 viewmat: torch.Tensor, intrinsics: torch.Tensor, width: int, height: int,
                                 param_groups: tuple[str, ...] = ("means", "quats", "log_scales", "logit_opacities",
                                                                  "sh_dc")) -> torch.Tensor:
    """`projection_jacobian` by autograd (its twin): Gaussians are independent, so one backward pass per
    attribute gives that row for every Gaussian at once (A passes, no loop over Gaussians).

    Args:
        means: [N, 3]; quats: raw wxyz [N, 4]; log_scales: [N, 3]; logit_opacities: [N]; sh_coeffs: [N, K, 3]
        sh_degree: active SH degree for the colour; viewmat [4, 4], intrinsics [4], width, height: the camera.
        param_groups: which raw parameters form the columns, a subsequence of
            ("means", "quats", "log_scales", "logit_opacities", "sh_dc", "sh_rest") in any order.
    Returns:
        J, in the dtype of `means`. [N, A, P]
    """
    _check_jacobian_inputs(means, log_scales, logit_opacities, sh_coeffs, sh_degree, param_groups)
    sh_dc, sh_rest = sh_coeffs[:, :1], sh_coeffs[:, 1:]
    raw = {"means": means, "quats": quats, "log_scales": log_scales, "logit_opacities": logit_opacities[:, None],
           "sh_dc": sh_dc, "sh_rest": sh_rest}
    leaves = {k: raw[k].detach().clone().requires_grad_(True) for k in param_groups}
    get = {k: leaves[k] if k in leaves else raw[k].detach() for k in raw}
    with torch.enable_grad():
        proj = project_gaussians(get["means"], get["quats"], torch.exp(get["log_scales"]), viewmat, intrinsics,
                                 width, height)
        colors = sh_to_colors(torch.cat([get["sh_dc"], get["sh_rest"]], dim=1), get["means"],
                              camera_center(viewmat).to(means.dtype), sh_degree)
        attrs = torch.cat([proj.means2d, proj.conics, torch.sigmoid(get["logit_opacities"]), colors], dim=1)  # [N, A]
        rows = []
        inputs = [leaves[k] for k in param_groups]
        for a in range(attrs.shape[1]):
            grads = torch.autograd.grad(attrs[:, a].sum(), inputs, retain_graph=True, allow_unused=True)
            rows.append(torch.cat([(g if g is not None else torch.zeros_like(x)).reshape(x.shape[0], -1)
                                   for g, x in zip(grads, inputs)], dim=1))
    return torch.stack(rows, dim=1)  # [N, A, P]
