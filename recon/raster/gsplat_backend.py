"""The `gsplat` backend (CUDA): gsplat's projection, tile intersection and rasterizer behind our API.

Written against gsplat 1.5 (`pip install gsplat==1.5.3`; it compiles its CUDA kernels on first
use). It calls gsplat's stages itself rather than `gsplat.rasterization`, for two reasons:

* `means2d`: gsplat's projection returns centres [1, N, 2] for the one camera. We take the view
  [N, 2] and hand `view[None]` to the rasterizer, so the [N, 2] tensor we return is a node of the
  graph and `retain_grad()` on it receives the densification gradient. (Returning
  `meta["means2d"][0]` after `gsplat.rasterization` gives a slice nothing downstream used: its
  `.grad` stays None and densification never clones or splits.)
* radii: called without opacities, gsplat's projection bounds each Gaussian by 3.33 sigma per
  image axis (`gsplat.rasterization` passes opacities and gets tighter bounds, which would change
  the screen-size pruning); we report the larger of the two, close to our 3-sigma-of-the-major-axis.

`max_weight` (each Gaussian's largest alpha x transmittance, which intensity-importance pruning
reads) is not reported by gsplat. It is computed on first use, without gradient, by the readable
torch reference (`rasterize_ref.rasterize_ref` on the same device, from `project_ref.project_ref`), so it equals
the cpu backend's to float rounding; training steps that never read it pay nothing.

Same conventions as the other backends (OpenCV world_to_cam, pixel centres at +0.5, 0.3 px^2
dilation, near plane 0.01, alpha skipped below 1/255, T stop at 1e-4). Known
differences, within the parity tests' tolerances: gsplat caps alpha at 0.999 (ours 0.99), decides
membership per 16x16 tile rather than per pixel of the footprint square (contributions up to alpha
~0.01 at footprint corners), and computes in float32 only: other inputs are rendered in float32
and the outputs returned in the inputs' dtype (gsplat's tile intersection reads a depth's bits as
a float32; float64 depths sorted wrong, then its rasterizer raised).
"""
from __future__ import annotations

import math

import torch

from recon.raster.types import LOWPASS, NEAR_PLANE, Camera, RenderOutput, TILE


def render_gsplat(means, quats, scales, opacities, colors, camera: Camera, background) -> RenderOutput:
    if means.dtype != torch.float32:              # gsplat's kernels are float32 only
        dtype = means.dtype
        f32 = [t.float() for t in (means, quats, scales, opacities, colors, background)]
        out = render_gsplat(*f32[:5], camera.to(torch.float32), f32[5])
        return RenderOutput(out.image.to(dtype), out.alpha.to(dtype), out.depth.to(dtype), out.radii,
                            out.means2d, lambda: out.max_weight.to(dtype))
    from gsplat import fully_fused_projection, isect_offset_encode, isect_tiles, rasterize_to_pixels

    W, H, C = camera.width, camera.height, colors.shape[1]
    radii, means2d_b, depths, conics, _ = fully_fused_projection(
        means, None, quats, scales, camera.world_to_cam[None], camera.K[None], W, H,
        eps2d=LOWPASS, near_plane=NEAR_PLANE, packed=False)
    means2d = means2d_b[0]                        # [N, 2] the tensor densification reads
    m2d = means2d[None]                           # [1, N, 2] what gsplat rasterizes (a child of means2d)
    tiles_w, tiles_h = math.ceil(W / TILE), math.ceil(H / TILE)
    _, isect_ids, flatten_ids = isect_tiles(m2d, radii, depths, TILE, tiles_w, tiles_h)
    offsets = isect_offset_encode(isect_ids, 1, tiles_w, tiles_h)
    feats = torch.cat([colors[None], depths[..., None]], dim=-1)        # [1, N, C + 1]: colour, depth
    out, alphas = rasterize_to_pixels(m2d, conics, feats, opacities[None], W, H, TILE, offsets, flatten_ids)
    alpha = alphas[0, ..., 0]
    image = out[0, ..., :C] + (1.0 - alpha)[..., None] * background
    depth = out[0, ..., C]
    r = radii[0]
    r = r.max(dim=-1).values if r.ndim == 2 else r   # gsplat >= 1.5 reports x and y radii

    def max_weight() -> torch.Tensor:
        from recon.raster.project_ref import project_ref
        from recon.raster.rasterize_ref import rasterize_ref

        with torch.no_grad():
            m, cn, d, rr = project_ref(means.detach(), quats.detach(), scales.detach(), camera)
            return rasterize_ref(m, cn, d, rr, opacities.detach(), colors.detach()[:, :1],
                                   background.detach()[:1], W, H)[3]

    return RenderOutput(image, alpha, depth, r.to(torch.int32), means2d, max_weight)
