#!/usr/bin/env python3
"""Independent numpy reference for the golden files of Eqs. (4)-(5) (golden/eq04-05-render).

Recomputes, for every case, the rendered image and the gradient of L = sum(d_image * image)
with respect to every parameter group, and compares them with the stored outputs within the
case's tolerance (|ref - golden| <= abs + rel |golden|). Exits non-zero on any mismatch.

Written from the equations, not from the Rust code:
- projection (Eq. 3), covariance (Eq. 1), camera and SH basis from tools/golden_reference.py
  (itself independent of the Rust code); opacity = sigmoid(logit); intensity by Eq. (2) (paper
  RIRF or X-Gaussian RIRF) or SH colour;
- compositing by brute force: for every pixel, every drawn Gaussian whose 16x16 tile rectangle
  holds the pixel's tile (tiles [floor((u - r)/16), ceil((u + r)/16)) clamped to the grid, the
  same for rows), in order of (depth rounded to float32, index); alpha = min(0.99, o G) with
  G = exp(-0.5 (A dx^2 + C dy^2) - B dx dy) at the pixel centre (col + 0.5, row + 0.5); skipped
  if the exponent is > 0 or alpha < 1/255; the pixel stops, without blending, when T (1 - alpha)
  < 1e-4; C = sum c alpha T + T_final * background. Vectorised over pixels, one Gaussian at a
  time (no tiles lists, no per-tile work);
- gradients by 5-point central finite differences (step 1e-4) of that render with every hard
  decision frozen at the unperturbed point (which (pixel, Gaussian) pairs blend, which alphas
  are clamped, the stop, the tile rectangles and the culling): the derivative of the forward
  pass as computed, which is what an analytic backward must return (a clamped alpha is the
  constant 0.99; a skipped or stopped pair contributes nothing).

Usage: python3 tools/render_reference.py   (from the repository root)
"""
import math
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import golden_reference as gr  # noqa: E402
from golden_io import arr, check_folders  # noqa: E402

TILE = 16
GROUPS = ["means", "log_scales", "quats", "opacity_logits", "features"]


def intensity(mode, k, f, mean, centre):
    if mode == "sh":
        v = np.asarray(mean) - np.asarray(centre)
        n = np.linalg.norm(v)
        basis = gr.sh_basis(v / n) if n > 0 else np.r_[gr.C0, np.zeros(15)]
        return max(0.0, 0.5 + float(basis[:k] @ f[:k]))
    s = float(gr.LAMBDA[:k] @ f[:k])
    return 1.0 / (1.0 + math.exp(-s)) if mode == "rirf-paper" else max(0.0, 0.5 + s)


def splats(inp, p):
    cam = gr.camera(inp["geometry"], inp["angle"])
    out = []
    for i in range(p["means"].shape[0]):
        mean2d, conic, radius, depth = gr.project(
            cam, p["means"][i], p["log_scales"][i], p["quats"][i])
        o = 1.0 / (1.0 + math.exp(-p["opacity_logits"][i]))
        c = intensity(inp["color_mode"], inp["active_features"], p["features"][i],
                      p["means"][i], cam["centre"])
        out.append((mean2d, conic, radius, depth, o, c))
    return cam, out


def tile_rect(u, v, r, tx, ty):
    x0 = min(max(math.floor((u - r) / TILE), 0), tx)
    x1 = min(max(math.ceil((u + r) / TILE), 0), tx)
    y0 = min(max(math.floor((v - r) / TILE), 0), ty)
    y1 = min(max(math.ceil((v + r) / TILE), 0), ty)
    return (x0, x1, y0, y1) if x0 < x1 and y0 < y1 else None


def render(inp, p, frozen=None):
    """Image (H, W) and the decisions; with `frozen`, the decisions of a previous call."""
    cam, sp = splats(inp, p)
    w, h = cam["W"], cam["H"]
    tx, ty = -(-w // TILE), -(-h // TILE)
    cols, rows = np.meshgrid(np.arange(w), np.arange(h))
    px, py = cols + 0.5, rows + 0.5
    ptx, pty = cols // TILE, rows // TILE
    if frozen is None:
        order = []
        for i, (m, _, r, d, _, _) in enumerate(sp):
            rect = tile_rect(m[0], m[1], r, tx, ty) if r > 0 else None
            if rect is not None:
                order.append((np.float32(d), i, rect))
        order.sort(key=lambda x: (x[0], x[1]))
        decisions = {"order": order, "blend": {}, "clamped": {}}
    else:
        order = frozen["order"]
        decisions = frozen
    t = np.ones((h, w))
    c = np.zeros((h, w))
    done = np.zeros((h, w), dtype=bool)
    for _, i, (x0, x1, y0, y1) in order:
        m, (a, b, cc), _, _, o, col = sp[i]
        dx, dy = px - m[0], py - m[1]
        power = -0.5 * (a * dx * dx + cc * dy * dy) - b * dx * dy
        og = o * np.exp(power)
        if frozen is None:
            alpha = np.minimum(0.99, og)
            inside = (ptx >= x0) & (ptx < x1) & (pty >= y0) & (pty < y1)
            live = inside & ~done & (power <= 0) & (alpha >= 1.0 / 255.0)
            stop = live & (t * (1 - alpha) < 1e-4)
            blend = live & ~stop
            done |= stop
            decisions["blend"][i] = blend
            decisions["clamped"][i] = og > 0.99
        else:
            blend = frozen["blend"][i]
            alpha = np.where(frozen["clamped"][i], 0.99, og)
        c = np.where(blend, c + col * alpha * t, c)
        t = np.where(blend, t * (1 - alpha), t)
    return c + t * inp["background"], decisions


def params(inp):
    return {g: arr(inp[g]).copy() for g in GROUPS}


def run_case(inp):
    p = params(inp)
    wts = arr(inp["d_image"])
    img, dec = render(inp, p)
    out = {"image": img}
    h = 1e-4
    for g in GROUPS:
        grad = np.zeros_like(p[g])
        flat = p[g].reshape(-1)
        gflat = grad.reshape(-1)
        for k in range(flat.size):
            x = flat[k]
            vals = []
            for d in (2 * h, h, -h, -2 * h):
                flat[k] = x + d
                vals.append(float(np.sum(wts * render(inp, p, dec)[0])))
            flat[k] = x
            gflat[k] = (-vals[0] + 8 * vals[1] - 8 * vals[2] + vals[3]) / (12 * h)
        out["d_" + g] = grad
    return out


def main():
    return check_folders(["eq04-05-render"], lambda _folder, _stem, inputs: run_case(inputs))


if __name__ == "__main__":
    sys.exit(main())
