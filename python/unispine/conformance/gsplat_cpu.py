"""gsplat v1.5.3's pure-PyTorch reference rasterizer on a CPU, as a conformance backend.

gsplat's ``gsplat/cuda/_torch_impl.py`` composes ``_quat_scale_to_covar_preci``,
``_fully_fused_projection``, ``_isect_tiles``, ``_isect_offset_encode`` and
``_rasterize_to_pixels``. Two pieces of the last one need CUDA: the pixel / Gaussian pair
kernel ``rasterize_to_indices_in_range`` (``gsplat.cuda._wrapper``, CUDA kernel
``rasterize_to_indices_3dgs``) and nerfacc's packed scans ``render_weight_from_alpha`` /
``accumulate_along_rays``. This module supplies small PyTorch stand-ins for the two, written
from what those kernels compute (not from their code), and installs them only while
``rasterization`` runs; gsplat's own functions do everything else. gsplat is installed from PyPI
(``BUILD_NO_CUDA=1 pip install gsplat==1.5.3``); nothing of it is copied here.

The stand-in pair kernel, per image, tile and pixel (sampled at (col + 0.5, row + 0.5)), walks
the tile's depth-sorted list in the batches [range_start, range_end) of tile_size^2 entries:
sigma = (A dx^2 + C dy^2)/2 + B dx dy with d = mean2d - pixel, alpha = min(0.999, o
exp(-sigma)); skip when sigma < 0 or alpha < 1/255; the pixel is done, without emitting the
entry, when T (1 - alpha) <= 1e-4; else emit (gaussian, pixel, image) and T <- T (1 - alpha),
T starting at the given transmittance (the constants of gsplat v1.5.3's
``gsplat/cuda/csrc/RasterizeToIndices3DGS.cu``). Pairs come out pixel by pixel in list order,
as nerfacc's packed layout needs. Hard decisions are not differentiated (gsplat recomputes
alpha with autograd in ``accumulate``).

The stand-in scans: the transmittance before each sample is the exclusive product of
(1 - alpha) over the earlier samples of its ray (left to right), weight = alpha T, and the
accumulation is a scatter-add of weight x value per ray.

It runs in the dtype of its inputs (float64 for the audit); ``_isect_tiles`` keys the sort on
the float32 bits of the depth whatever the dtype, as gsplat does, and the keys are sorted
stably (ties of the float32 depth in Gaussian index order, as gsplat's CUDA radix sort leaves
them; ``torch.sort`` alone is not stable).
"""

import contextlib
import sys
import types

import torch

TILE = 16


def _indices_in_range(range_start, range_end, transmittances, means2d, conics, opacities,
                      image_width, image_height, tile_size, isect_offsets, flatten_ids):
    """Stand-in for ``gsplat.cuda._wrapper.rasterize_to_indices_in_range`` (see the module
    docs). Returns (gaussian_ids, pixel_ids, image_ids), int64."""
    image_dims = means2d.shape[:-2]
    n = means2d.shape[-2]
    n_img = 1
    for d in image_dims:
        n_img *= d
    th, tw = isect_offsets.shape[-2:]
    means2d = means2d.detach().reshape(n_img, n, 2)
    conics = conics.detach().reshape(n_img, n, 3)
    opac = opacities.detach().reshape(n_img, n)
    trans0 = transmittances.detach().reshape(n_img, image_height, image_width).to(means2d.dtype)
    offsets = isect_offsets.reshape(-1).tolist() + [len(flatten_ids)]
    flat = flatten_ids.tolist()
    block = tile_size * tile_size
    out_g, out_p, out_i = [], [], []
    for img in range(n_img):
        pix_lists = {}
        for ty in range(th):
            for tx in range(tw):
                t = (img * th + ty) * tw + tx
                lo, hi = offsets[t], offsets[t + 1]
                lo, hi = lo + range_start * block, min(hi, lo + range_end * block)
                if lo >= hi:
                    continue
                ids = torch.tensor(flat[lo:hi], dtype=torch.int64)      # flat ids in [I * N]
                g = ids % n
                rows = torch.arange(ty * tile_size, min((ty + 1) * tile_size, image_height))
                cols = torch.arange(tx * tile_size, min((tx + 1) * tile_size, image_width))
                if len(rows) == 0 or len(cols) == 0:
                    continue
                rr, cc = torch.meshgrid(rows, cols, indexing="ij")
                rr, cc = rr.reshape(-1), cc.reshape(-1)
                px = cc.to(means2d.dtype)[:, None] + 0.5
                py = rr.to(means2d.dtype)[:, None] + 0.5
                dx = means2d[img, g, 0][None] - px
                dy = means2d[img, g, 1][None] - py
                ca, cb, cc_ = conics[img, g, 0], conics[img, g, 1], conics[img, g, 2]
                sigma = 0.5 * (ca * dx * dx + cc_ * dy * dy) + cb * dx * dy
                alpha = torch.clamp(opac[img, g][None] * torch.exp(-sigma), max=0.999)
                keep = (sigma >= 0) & (alpha >= 1.0 / 255.0)
                factor = torch.where(keep, 1.0 - alpha, torch.ones_like(alpha))
                t0 = trans0[img, rr, cc][:, None]
                nxt = torch.cumprod(torch.cat([t0, factor], 1), 1)[:, 1:]
                stop = keep & (nxt <= 1e-4)
                after = torch.cumsum(stop.to(torch.int64), 1) > 0
                emit = keep & ~after
                for k in range(len(rr)):
                    sel = g[emit[k]]
                    if len(sel):
                        pid = int(rr[k]) * image_width + int(cc[k])
                        pix_lists[pid] = sel
        for pid in sorted(pix_lists):
            sel = pix_lists[pid]
            out_g.append(sel)
            out_p.append(torch.full_like(sel, pid))
            out_i.append(torch.full_like(sel, img))
    if not out_g:
        e = torch.zeros(0, dtype=torch.int64)
        return e, e, e
    return torch.cat(out_g), torch.cat(out_p), torch.cat(out_i)


def _segments(ray_indices):
    """Row and column of each packed sample in a [rays, longest] layout (rays sorted)."""
    n = len(ray_indices)
    start = torch.ones(n, dtype=torch.bool)
    start[1:] = ray_indices[1:] != ray_indices[:-1]
    row = torch.cumsum(start.to(torch.int64), 0) - 1
    first = torch.nonzero(start).reshape(-1)
    col = torch.arange(n) - first[row]
    return row, col, int(row[-1]) + 1 if n else 0, int(col.max()) + 1 if n else 0


def _render_weight_from_alpha(alphas, ray_indices=None, n_rays=None, **_):
    """Stand-in for ``nerfacc.render_weight_from_alpha`` (packed): (weights, transmittance)."""
    if len(alphas) == 0:
        return alphas, alphas
    row, col, nr, nc = _segments(ray_indices)
    grid = torch.ones((nr, nc + 1), dtype=alphas.dtype)
    grid = grid.index_put((row, col + 1), 1.0 - alphas)
    trans = torch.cumprod(grid, 1)[row, col]
    return trans * alphas, trans


def _accumulate_along_rays(weights, values=None, ray_indices=None, n_rays=None):
    """Stand-in for ``nerfacc.accumulate_along_rays``: per-ray sum of weight x value."""
    src = weights[:, None] if values is None else weights[:, None] * values
    out = torch.zeros((n_rays, src.shape[-1]), dtype=src.dtype)
    return out.index_add(0, ray_indices, src)


@contextlib.contextmanager
def cpu_stand_ins():
    """Install the two stand-ins (a ``nerfacc`` module and the pair kernel) while active."""
    import gsplat.cuda._wrapper as wrapper
    fake = types.ModuleType("nerfacc")
    fake.render_weight_from_alpha = _render_weight_from_alpha
    fake.accumulate_along_rays = _accumulate_along_rays
    saved_mod = sys.modules.get("nerfacc")
    saved_fn = wrapper.rasterize_to_indices_in_range
    sys.modules["nerfacc"] = fake
    wrapper.rasterize_to_indices_in_range = _indices_in_range
    try:
        yield
    finally:
        wrapper.rasterize_to_indices_in_range = saved_fn
        if saved_mod is None:
            sys.modules.pop("nerfacc", None)
        else:
            sys.modules["nerfacc"] = saved_mod


def rasterization(means, quats, scales, opacities, colors, viewmats, Ks, width, height, *,
                  sh_degree=None, backgrounds=None, camera_model="pinhole", eps2d=0.3,
                  near_plane=0.01, far_plane=1e10, tile_size=TILE):
    """gsplat's ``rasterization`` (classic mode, dense, no batch dims) from the functions of
    ``gsplat/cuda/_torch_impl.py`` on a CPU. Arguments as gsplat's: means [N, 3], quats [N, 4]
    (w, x, y, z), scales [N, 3], opacities [N], colors [N, D] or SH coefficients [N, K, D] with
    ``sh_degree``, viewmats [C, 4, 4], Ks [C, 3, 3]. Returns (render_colors [C, H, W, D],
    render_alphas [C, H, W, 1])."""
    from gsplat.cuda import _torch_impl as ti

    c = viewmats.shape[0]
    n = means.shape[0]
    covars, _ = ti._quat_scale_to_covar_preci(quats, scales, compute_preci=False)
    radii, means2d, depths, conics, _ = ti._fully_fused_projection(
        means, covars, viewmats, Ks, width, height, eps2d=eps2d, near_plane=near_plane,
        far_plane=far_plane, camera_model=camera_model)
    opac = opacities[None].expand(c, n)
    if sh_degree is None:
        cols = colors[None].expand(c, n, colors.shape[-1])
    else:
        campos = torch.inverse(viewmats)[:, :3, 3]
        dirs = means[None] - campos[:, None]
        d = colors.shape[-1]
        k = colors.shape[-2]
        # _spherical_harmonics takes 3 channels: evaluate per channel in groups of 3.
        pad = (-d) % 3
        co = torch.cat([colors, colors[..., :1].expand(n, k, pad)], -1) if pad else colors
        out = []
        for ch in range(0, co.shape[-1], 3):
            sh = co[..., ch:ch + 3][None].expand(c, n, k, 3)
            out.append(ti._spherical_harmonics(sh_degree, dirs, sh))
        cols = torch.clamp_min(torch.cat(out, -1)[..., :d] + 0.5, 0.0)
    tw, th = -(-width // tile_size), -(-height // tile_size)
    # gsplat's CUDA path sorts the (tile | depth bits) keys with a stable radix sort over the
    # intersections emitted in Gaussian order, so Gaussians whose depths round to the same
    # float32 stay in index order; `_isect_tiles(sort=True)` uses torch.sort, which is not
    # stable. The keys are sorted here as the CUDA path does.
    _, isect_ids, flatten_ids = ti._isect_tiles(means2d, radii, depths, tile_size, tw, th,
                                                sort=False)
    isect_ids, order = torch.sort(isect_ids, stable=True)
    flatten_ids = flatten_ids[order]
    offsets = ti._isect_offset_encode(isect_ids, c, tw, th)
    with cpu_stand_ins():
        return ti._rasterize_to_pixels(means2d, conics, cols, opac, width, height, tile_size,
                                       offsets, flatten_ids, backgrounds=backgrounds)
