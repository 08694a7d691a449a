"""gsplat 1.5.3 on the CPU: the real package (its Python API, argument checks, channel padding, tile
bookkeeping) with only its compiled kernels replaced, so the gsplat backend runs in every CI.

* projection: gsplat's own torch reference (`_torch_impl._fully_fused_projection`, covariances from
  `_quat_scale_to_covar_preci`), in place of `_FullyFusedProjection` (autograd gives the backward);
* tile intersection and offsets: gsplat's torch references of the `intersect_tile` and
  `intersect_offset` kernels;
* rasterization: `rasterize_tiles` below, the forward of `RasterizeToPixels3DGSFwd.cu` in torch
  (per 16x16 tile, depth order, alpha = min(0.999, o exp(-sigma)), skipped below 1/255 or sigma < 0,
  a pixel done when T would fall to 1e-4), in place of `_RasterizeToPixels` (autograd: the backward).

`install(monkeypatch)` puts them in place; `calls` records the dtypes the kernels were handed."""
from __future__ import annotations

import inspect

import torch

ALPHA_THRESHOLD = 1.0 / 255.0
T_STOP = 1e-4
calls: list[tuple[str, torch.dtype]] = []


def rasterize_tiles(means2d, conics, colors, opacities, backgrounds, masks, width, height, tile_size,
                    isect_offsets, flatten_ids, absgrad=False):
    """gsplat's rasterize-to-pixels forward, differentiable by autograd: -> ([..., H, W, C], [..., H, W, 1])."""
    image_dims = means2d.shape[:-2]
    N, C = means2d.shape[-2], colors.shape[-1]
    I = int(torch.tensor(image_dims).prod()) if image_dims else 1
    m2d, con, col, opa = (t.reshape(I, N, -1) for t in (means2d, conics, colors, opacities[..., None]))
    offsets = isect_offsets.reshape(-1)            # every image's tiles, in order: a tile's range ends at the next's start
    tiles_h, tiles_w = isect_offsets.shape[-2:]
    n_isects = flatten_ids.numel()
    images, alphas = [], []
    for i in range(I):
        img = [[None] * tiles_w for _ in range(tiles_h)]
        alp = [[None] * tiles_w for _ in range(tiles_h)]
        for ty in range(tiles_h):
            for tx in range(tiles_w):
                tile = (i * tiles_h + ty) * tiles_w + tx
                start = int(offsets[tile])
                end = int(offsets[tile + 1]) if tile + 1 < len(offsets) else n_isects
                ys = torch.arange(ty * tile_size, min((ty + 1) * tile_size, height), dtype=m2d.dtype) + 0.5
                xs = torch.arange(tx * tile_size, min((tx + 1) * tile_size, width), dtype=m2d.dtype) + 0.5
                py, px = torch.meshgrid(ys, xs, indexing="ij")                   # [h, w] pixel centres
                ids = flatten_ids[start:end].long() - i * N                      # depth order
                T_final = torch.ones_like(px)
                out = torch.zeros(*px.shape, C, dtype=col.dtype)
                if len(ids):
                    mu, cn, o = m2d[i, ids], con[i, ids], opa[i, ids, 0]         # [K, 2], [K, 3], [K]
                    dx = mu[:, 0, None, None] - px                               # [K, h, w]
                    dy = mu[:, 1, None, None] - py
                    sigma = 0.5 * (cn[:, 0, None, None] * dx * dx + cn[:, 2, None, None] * dy * dy) \
                        + cn[:, 1, None, None] * dx * dy
                    alpha = torch.clamp(o[:, None, None] * torch.exp(-sigma), max=0.999)
                    a = torch.where((sigma >= 0) & (alpha >= ALPHA_THRESHOLD), alpha, torch.zeros_like(alpha))
                    next_T = torch.cumprod(1.0 - a, dim=0)                      # T after each Gaussian
                    used = next_T > T_STOP                                       # before the pixel is done
                    T_before = torch.cat([torch.ones_like(next_T[:1]), next_T[:-1]], 0)
                    vis = torch.where(used, a * T_before, torch.zeros_like(a))  # [K, h, w]
                    out = torch.einsum("khw,kc->hwc", vis, col[i, ids])
                    T_final = torch.prod(torch.where(used, 1.0 - a, torch.ones_like(a)), dim=0)
                if backgrounds is not None:
                    out = out + T_final[..., None] * backgrounds.reshape(I, C)[i]
                img[ty][tx], alp[ty][tx] = out, (1.0 - T_final)[..., None]
        images.append(torch.cat([torch.cat(row, 1) for row in img], 0))
        alphas.append(torch.cat([torch.cat(row, 1) for row in alp], 0))
    return (torch.stack(images).reshape(*image_dims, height, width, C),
            torch.stack(alphas).reshape(*image_dims, height, width, 1))


def install(monkeypatch) -> None:
    """Replace gsplat's compiled kernels by the torch versions above (the package's API stays its own)."""
    import gsplat.cuda._wrapper as W
    from gsplat.cuda import _torch_impl as T

    real_projection = inspect.signature(W._FullyFusedProjection.forward)
    real_raster = inspect.signature(W._RasterizeToPixels.forward)

    class Projection:
        @staticmethod
        def apply(*args):
            a = real_projection.bind(None, *args).arguments                 # the kernel's own argument list
            calls.append(("projection", a["means"].dtype))
            covars = a["covars"]
            if covars is None:
                covars, _ = T._quat_scale_to_covar_preci(a["quats"], a["scales"], compute_preci=False)
            radii, means2d, depths, conics, comp = T._fully_fused_projection(
                a["means"], covars, a["viewmats"], a["Ks"], a["width"], a["height"], a["eps2d"], a["near_plane"],
                a["far_plane"], a["calc_compensations"], a["camera_model"])
            clipped = (radii <= a["radius_clip"]).all(-1, keepdim=True)
            return torch.where(clipped, torch.zeros_like(radii), radii), means2d, depths, conics, comp

    class Raster:
        @staticmethod
        def apply(*args):
            a = real_raster.bind(None, *args).arguments
            calls.append(("raster", a["means2d"].dtype))
            return rasterize_tiles(*(a[k] for k in list(a)[1:]))

    def kernel(name):
        def intersect_tile(means2d, radii, depths, image_ids, gaussian_ids, I, tile_size, tile_w, tile_h, sort, segmented):
            calls.append(("intersect_tile", depths.dtype))
            return T._isect_tiles(means2d, radii, depths, tile_size, tile_w, tile_h, sort)

        def intersect_offset(isect_ids, n_images, tile_w, tile_h):
            return T._isect_offset_encode(isect_ids, n_images, tile_w, tile_h)

        kernels = {"intersect_tile": intersect_tile, "intersect_offset": intersect_offset}
        if name not in kernels:
            raise NotImplementedError(f"gsplat kernel {name!r} has no CPU stand-in")
        return kernels[name]

    monkeypatch.setattr(W, "_FullyFusedProjection", Projection)
    monkeypatch.setattr(W, "_RasterizeToPixels", Raster)
    monkeypatch.setattr(W, "_make_lazy_cuda_func", kernel)
    calls.clear()
