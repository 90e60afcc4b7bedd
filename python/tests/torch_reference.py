"""An independent rasterizer in plain PyTorch (autograd for the gradients), written from the
conventions documented in `golden/README.md` and `unispine.rasterize`'s docstring: brute force
over every (pixel, Gaussian) pair, no tiles lists, no pixel boxes, no hand-written backward.

Hard decisions (culling, radius, tile rectangles, the alpha skip, the transmittance stop) are
taken under `torch.no_grad()` and then held fixed, as the reference does; the clamp of alpha at
0.99 is `torch.clamp` (zero derivative where it is active).
"""

import math

import torch

TILE = 16
LAMBDA = torch.tensor([
    0.28209479177387814, -0.4886025119029199, 0.4886025119029199, -0.4886025119029199,
    1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
    0.5462742152960396, -0.5900435899266435, 2.890611442640554, -0.4570457994644658,
    0.3731763325901154, -0.4570457994644658, 1.445305721320277, -0.5900435899266435,
], dtype=torch.float64)


def rotation(q):
    """Rotation matrices [N, 3, 3] of unnormalised quaternions (w, x, y, z)."""
    q = q / q.norm(dim=1, keepdim=True)
    w, x, y, z = q.unbind(1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=1).reshape(-1, 3, 3)


def sh_basis(d):
    """The 16 real SH basis functions (3DGS order and signs) of unit directions d [N, 3]."""
    x, y, z = d.unbind(1)
    xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
    c = LAMBDA.abs().tolist()
    return torch.stack([
        torch.full_like(x, c[0]), -c[1] * y, c[1] * z, -c[1] * x,
        c[4] * xy, -c[4] * yz, c[6] * (2 * zz - xx - yy), -c[4] * xz, c[8] * (xx - yy),
        -c[9] * y * (3 * xx - yy), c[10] * xy * z, -c[11] * y * (4 * zz - xx - yy),
        c[12] * z * (2 * zz - 3 * xx - 3 * yy), -c[11] * x * (4 * zz - xx - yy),
        c[14] * z * (xx - yy), -c[9] * x * (xx - 3 * yy),
    ], dim=1)


def render(means, quats, log_scales, opacity_logits, features, viewmat, K, width, height,
           color_mode="rirf-paper", active=16, background=0.0):
    """Image [H, W] of one pinhole camera (viewmat [4, 4], K [3, 3] float64 tensors)."""
    rot, tvec = viewmat[:3, :3], viewmat[:3, 3]
    centre = -(rot.T @ tvec)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    # Eq. (1): Sigma = R S S R^T.
    r = rotation(quats)
    m = r * torch.exp(log_scales)[:, None, :]
    sigma = m @ m.transpose(1, 2)
    # Eq. (3): camera space, EWA Jacobian with the 1.3 tan(fov/2) clamp inside J.
    t = (means - centre) @ rot.T
    x, y, z = t.unbind(1)
    lim_x, lim_y = 1.3 * width / (2 * fx), 1.3 * height / (2 * fy)
    tx = torch.clamp(x / z, -lim_x, lim_x)
    ty = torch.clamp(y / z, -lim_y, lim_y)
    zero = torch.zeros_like(z)
    jac = torch.stack([
        torch.stack([fx / z, zero, -fx * tx / z], 1),
        torch.stack([zero, fy / z, -fy * ty / z], 1),
    ], 1)
    tm = jac @ rot
    cov = tm @ sigma @ tm.transpose(1, 2) + 0.3 * torch.eye(2, dtype=means.dtype)
    a, b, c = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    det = a * c - b * b
    conic = torch.stack([c / det, -b / det, a / det], 1)
    u = fx * x / z + cx
    v = fy * y / z + cy
    opacity = torch.sigmoid(opacity_logits)
    if color_mode == "rirf-paper":
        color = torch.sigmoid(features[:, :active] @ LAMBDA[:active])
    elif color_mode == "sh":
        d = means - centre
        d = d / d.norm(dim=1, keepdim=True)
        color = torch.clamp(0.5 + (sh_basis(d)[:, :active] * features[:, :active]).sum(1), min=0)
    else:
        raise ValueError(color_mode)

    with torch.no_grad():
        mid = 0.5 * (a + c)
        lmax = mid + torch.sqrt(torch.clamp(mid * mid - det, min=0.1))
        radius = torch.ceil(3 * torch.sqrt(lmax))
        visible = (z > 0.2) & (det > 0) & (u + radius > 0) & (u - radius < width) \
            & (v + radius > 0) & (v - radius < height)
        tiles_x, tiles_y = math.ceil(width / TILE), math.ceil(height / TILE)
        tx0 = torch.clamp(torch.floor((u - radius) / TILE), 0, tiles_x)
        tx1 = torch.clamp(torch.ceil((u + radius) / TILE), 0, tiles_x)
        ty0 = torch.clamp(torch.floor((v - radius) / TILE), 0, tiles_y)
        ty1 = torch.clamp(torch.ceil((v + radius) / TILE), 0, tiles_y)
        # Sort by (depth rounded to float32, index).
        order = sorted(range(len(z)), key=lambda i: (float(z[i].to(torch.float32)), i))
        order = torch.tensor(order, dtype=torch.long)

    rows, cols = torch.meshgrid(torch.arange(height, dtype=means.dtype),
                                torch.arange(width, dtype=means.dtype), indexing="ij")
    px, py = cols.reshape(-1, 1) + 0.5, rows.reshape(-1, 1) + 0.5   # [P, 1]
    dx, dy = px - u[order], py - v[order]                             # [P, N]
    ca, cb, cc = conic[order].unbind(1)
    power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
    alpha = torch.clamp(opacity[order] * torch.exp(power), max=0.99)
    with torch.no_grad():
        ptx = torch.floor(px / TILE)
        pty = torch.floor(py / TILE)
        keep = visible[order] & (ptx >= tx0[order]) & (ptx < tx1[order]) \
            & (pty >= ty0[order]) & (pty < ty1[order]) & (power <= 0) & (alpha >= 1 / 255)
        a_k = torch.where(keep, alpha, torch.zeros_like(alpha))
        t_before = torch.cumprod(torch.cat([torch.ones_like(a_k[:, :1]), 1 - a_k[:, :-1]], 1), 1)
        # Exclusive stop: the first kept entry with T (1 - alpha) < 1e-4 and every later one
        # are not blended.
        stop = keep & (t_before * (1 - a_k) < 1e-4)
        after = torch.cumsum(stop.to(torch.int64), 1) > 0
        keep = keep & ~after
    a_k = torch.where(keep, alpha, torch.zeros_like(alpha))
    trans = torch.cumprod(torch.cat([torch.ones_like(a_k[:, :1]), 1 - a_k], 1), 1)
    image = (color[order] * a_k * trans[:, :-1]).sum(1) + trans[:, -1] * background
    return image.reshape(height, width)
