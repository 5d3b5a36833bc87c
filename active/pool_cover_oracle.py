"""COVER's direction coverage measured over the pool's poses: how well the views taken so far cover each Gaussian as
seen from every pose of the pool (the poses the scene will plausibly be looked at from), as a counted oracle.

COVER (`active.cover_oracle`) scores a candidate by how new its own view directions are. Here the question is the
I-optimal one, asked geometrically: after adding v, how far is each pool pose's view of each Gaussian from the
nearest captured direction? With E_{c,i}(S) = min(1, min_{s in S, i in F(s)} (1 - d_c,i . d_s,i) / 2) for a Gaussian
i in pose c's frustum F(c) (1 where no view of S sees it), the objective and the gain are

    F(S) = sum_{c in pool} sum_{i in F(c)} w_i E_{c,i}(S),        gain(v | S) = F(S) - F(S + {v}) >= 0,

with w_i the opacity. F(S) - F(S + v) is a facility-location gain (each (c, i) pair takes the nearest captured
direction), so it only shrinks as S grows: monotone submodular, and lazy greedy over it is exact. Pool = every camera
of the acquisition step (captured views and candidates); the test poses are never used. No Fisher pass, no
rendering: a gain costs O(|pool| n_v), n_v the Gaussians the candidate sees.

With `weight="pixels"` the weight of a pair is pose-dependent, w_c,i = the pixels of c's image Gaussian i paints
(its blend weight summed, occlusion included, `active.blend_weights`), and "c sees i" means i paints at least
`VISIBLE_PIXELS` of c's image instead of "i's centre lies in c's frustum": F(S) is then the pool's rendered pixels
weighted by how far their Gaussians lie, in direction, from the nearest captured view that actually sees them.
One render (forward and backward) per pose; the gains stay facility-location gains.
"""
from __future__ import annotations

import torch

from active.blend_weights import VISIBLE_PIXELS, blend_weights
from active.cover_oracle import frustum_directions
from gaussian_renderer.settings import RasterSettings
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from utils import system_memory
from utils.errors import UserError


BYTES_PER_PAIR = 91  # per (pose, Gaussian): directions 24, error 8, inside 1; a gain's gathers and temporaries 58
POSE_WEIGHT_BYTES = 16  # per pair with pose-dependent weights: the weight 8 and its gather 8
POOL_WEIGHTS = ("opacity", "pixels")  # cover_pool's --pool_weight


def check_memory(num_poses: int, num_gaussians: int, pose_weights: bool = False) -> None:
    """A `UserError` when the oracle's [poses, N] arrays would take more than half of the available memory."""
    per_pair = BYTES_PER_PAIR + (POSE_WEIGHT_BYTES if pose_weights else 0)
    need, available = num_poses * num_gaussians * per_pair, system_memory.available_memory_bytes()
    if need > available // 2:
        raise UserError(f"cover_pool over {num_poses} poses and {num_gaussians} Gaussians needs about "
                        f"{need / 2**30:.1f} GiB, more than half of the {available / 2**30:.1f} GiB available: use "
                        "fewer candidates, or --method cover (one pose at a time)")


class PoolCoverageOracle:
    """The counted pool-coverage gain oracle of one acquisition step (the `GainOracle` protocol: gain, commit,
    evaluated)."""

    views_computed = 0  # no Fisher pass: what acquisition reports for the Fisher oracles
    fisher_seconds = 0.0

    def __init__(self, means: torch.Tensor, weights: torch.Tensor, cameras: list[Camera], train_views: list[int],
                 inside: torch.Tensor | None = None):
        """Args:
            means: Gaussian centres. [N, 3]
            weights: per-Gaussian weights w_i >= 0 (opacities) [N], or per pair w_c,i [N, V].
            cameras: every camera of the pool (view id = index); all of them are the poses covered.
            train_views: the views taken so far.
            inside: which pose sees which Gaussian [N, V] bool (default: the centre lies in the pose's frustum).
        """
        means = means.detach().double().cpu()
        check_memory(len(cameras), means.shape[0], pose_weights=weights.ndim == 2)
        weights = weights.detach().double().cpu()
        self.weights = weights if weights.ndim == 2 else weights.reshape(-1, 1)  # [N, V] or [N, 1]
        frames = [frustum_directions(means, camera) for camera in cameras]
        # Gaussian-major, so that a candidate's visible Gaussians are whole rows
        if inside is None:
            inside = torch.stack([seen for seen, _ in frames], dim=1)
        self.inside = inside.cpu()  # [N, V] bool: pose c sees Gaussian i
        self.directions = torch.stack([dirs for _, dirs in frames], dim=1).permute(2, 0, 1).contiguous()  # [3, N, V]
        self.error = self.inside.double()  # [N, V] E_{c,i}(S): 1 where c sees i and S is empty, 0 where c does not
        self.evaluated = 0
        for view in train_views:
            self.commit(view)

    @classmethod
    def for_model(cls, gaussians: GaussianModel, cameras: list[Camera], train_views: list[int],
                  weight: str = "opacity", settings: RasterSettings | None = None) -> PoolCoverageOracle:
        """The oracle over a model's Gaussians: their centres, weighted by their opacities (`weight="opacity"`) or by
        the pixels each paints in each pose (`weight="pixels"`, one render per pose with `settings`)."""
        if weight == "opacity":
            return cls(gaussians.means, gaussians.opacities, cameras, train_views)
        if weight != "pixels":
            raise ValueError(f"weight must be one of {', '.join(POOL_WEIGHTS)}, got {weight!r}")
        check_memory(len(cameras), gaussians.means.shape[0], pose_weights=True)  # before the renders
        pixels = torch.stack([blend_weights(gaussians, camera, settings) for camera in cameras], dim=1)  # [N, V]
        return cls(gaussians.means, pixels, cameras, train_views, inside=pixels >= VISIBLE_PIXELS)

    def _error_with(self, view_id: int) -> tuple[torch.Tensor, torch.Tensor]:
        """The rows E(S + {v}) changes, those of the Gaussians v sees: (their ids [n], E(S + {v}) there [n, V])."""
        rows = self.inside[:, view_id].nonzero().squeeze(1)  # [n]
        d = self.directions[:, rows]  # [3, n, V]
        ahead = d[:, :, view_id:view_id + 1]  # [3, n, 1] d_v,i
        cos = d[0] * ahead[0]
        cos.addcmul_(d[1], ahead[1]).addcmul_(d[2], ahead[2])  # [n, V] d_c,i . d_v,i
        taken = cos.neg_().add_(1.0).mul_(0.5).masked_fill_(~self.inside[rows], torch.inf)  # (1 - cos) / 2
        return rows, torch.minimum(self.error[rows], taken)

    def objective(self) -> float:
        """F(S): the weighted uncovered direction over every (pose, Gaussian) pair."""
        return float((self.error * self.weights).sum())

    def gain(self, view_id: int) -> float:
        """gain(v | S) = F(S) - F(S + {v}): one oracle evaluation."""
        self.evaluated += 1
        rows, error = self._error_with(view_id)
        return float(((self.error[rows] - error) * self.weights[rows]).sum())

    def commit(self, view_id: int) -> None:
        """S <- S + {v} (not an oracle evaluation)."""
        rows, error = self._error_with(view_id)
        self.error[rows] = error

    def snapshot(self) -> torch.Tensor:
        """The committed state (E(S) for every pair), for `restore`: lets a selector score another set, then return."""
        return self.error.clone()

    def restore(self, state: torch.Tensor) -> None:
        """Return to a `snapshot`'s state (not an oracle evaluation; the evaluated count is kept)."""
        self.error = state.clone()

    def reset_counts(self) -> None:
        self.evaluated = 0
