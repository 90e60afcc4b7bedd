#!/usr/bin/env python3
"""Independent numpy check of the neural-field encoder golden files (golden/field-*).

Each encoder is written here from its published conventions (golden/README.md):
- frequency: NeRF positional encoding [x, sin(2^k x), cos(2^k x)] of the point in metres;
- hash grid: torch-ngp's HashEncoder as NAF uses it (per-level scale 2, pos = u (R - 1) + 1/2,
  dense levels while (R + 1)^3 <= T, else the XOR hash with primes 1, 19349663, 83492791);
- TensoRF VM: SAX-NeRF's TensorfEncoder, every read a PyTorch F.grid_sample(align_corners=True)
  with zero padding, written here as PyTorch's bilinear formulas; the upstream line factor reads
  the plane at grid (0, c), the corrected one the line;
- dense grid: trilinear interpolation of an [z, y, x, F] table, align-corners or torch-ngp
  level mapping.
The forwards are complex-safe (cells and taps chosen on the real part), and every gradient of
L = sum(d_out * encoding), with respect to each parameter and each point coordinate, is the
complex-step derivative Im L(x + i h e_j) / h, h = 1e-30 (no hand-written backward).
Compares with the stored outputs within each file's tolerance; exits non-zero on a mismatch.

Usage: python3 tools/field_reference.py   (from the repository root)
"""
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from golden_io import arr, check_folders  # noqa: E402

H = 1e-30
MASK = 0xFFFFFFFF


def trilinear(lookup, pos):
    """sum over the 8 corners floor(pos) + bits of prod_d (frac_d or 1 - frac_d) lookup(corner)."""
    base = np.floor(pos.real).astype(np.int64)
    frac = pos - base
    acc = 0
    for c in range(8):
        bits = [(c >> d) & 1 for d in range(3)]
        w = 1
        for d in range(3):
            w = w * (frac[d] if bits[d] else 1 - frac[d])
        acc = acc + w * lookup(base[0] + bits[0], base[1] + bits[1], base[2] + bits[2])
    return acc


def frequency(enc, params, x):
    out = [x]
    for k in range(enc["bands"]):
        f = 2.0 ** k
        out += [np.sin(f * x), np.cos(f * x)]
    return np.concatenate(out)


def hash_offsets(enc):
    t = 1 << enc["log2_table_size"]
    offs = [0]
    for level in range(enc["levels"]):
        r = enc["base_resolution"] << level
        offs.append(offs[-1] + min(t, (r + 1) ** 3))
    return offs


def hash_grid(enc, params, x):
    table = params["table"]
    t = 1 << enc["log2_table_size"]
    b = enc["bound"]
    offs = hash_offsets(enc)
    feats = []
    for level in range(enc["levels"]):
        r = enc["base_resolution"] << level
        size = offs[level + 1] - offs[level]
        dense = (r + 1) ** 3 <= t

        def lookup(i, j, k, r=r, size=size, dense=dense, level=level):
            if dense:
                idx = i + (r + 1) * (j + (r + 1) * k)
            else:
                idx = ((i * 1) & MASK) ^ ((j * 19349663) & MASK) ^ ((k * 83492791) & MASK)
            return table[offs[level] + idx % size]

        u = (x + b) / (2 * b)
        feats.append(trilinear(lookup, u * (r - 1) + 0.5))
    return np.concatenate(feats)


def dense_grid(enc, params, x):
    table = params["table"]  # [z, y, x, F]
    n = enc["resolution"]
    b = enc["bound"]
    if enc["map"] == "align-corners":
        pos = (x / b + 1) / 2 * (n - 1)
    else:
        pos = (x + b) / (2 * b) * (n - 2) + 0.5

    def lookup(i, j, k):
        if 0 <= i < n and 0 <= j < n and 0 <= k < n:
            return table[k, j, i]
        return np.zeros(table.shape[-1])

    return trilinear(lookup, pos)


def grid_sample(img, gx, gy):
    """PyTorch F.grid_sample(img[None], grid, mode='bilinear', padding_mode='zeros',
    align_corners=True) at one grid point; img is [C, H, W]."""
    _, h, w = img.shape
    ix = (gx + 1) / 2 * (w - 1)
    iy = (gy + 1) / 2 * (h - 1)
    x0 = int(np.floor(ix.real))
    y0 = int(np.floor(iy.real))
    x1, y1 = x0 + 1, y0 + 1
    nw = (x1 - ix) * (y1 - iy)
    ne = (ix - x0) * (y1 - iy)
    sw = (x1 - ix) * (iy - y0)
    se = (ix - x0) * (iy - y0)

    def at(xx, yy):
        if 0 <= xx < w and 0 <= yy < h:
            return img[:, yy, xx]
        return np.zeros(img.shape[0])

    return nw * at(x0, y0) + ne * at(x1, y0) + sw * at(x0, y1) + se * at(x1, y1)


def tensorf_vm(enc, params, x):
    mat = [[0, 1], [0, 2], [1, 2]]
    vec = [2, 1, 0]
    c = x / enc["bound"]
    feats = []
    for i in range(3):
        plane = params["planes"][i]  # [C, N, N]
        p = grid_sample(plane, c[mat[i][0]], c[mat[i][1]])
        if enc["lines"] == "upstream":
            line = grid_sample(plane, 0.0, c[vec[i]])
        else:
            line = grid_sample(params["lines"][i][:, :, None], 0.0, c[vec[i]])
        feats.append(p * line)
    return params["basis"] @ np.concatenate(feats)


ENCODERS = {
    "frequency": frequency,
    "hash-grid": hash_grid,
    "dense-grid": dense_grid,
    "tensorf-vm": tensorf_vm,
}


def loss(enc, params, pts, d_out):
    f = ENCODERS[enc["kind"]]
    return sum(np.sum(d_out[n] * f(enc, params, pts[n])) for n in range(len(pts)))


def run_case(folder, stem, inputs):
    enc = inputs["encoder"]
    if enc["kind"] == "hash-grid":
        assert hash_offsets(enc) == enc["offsets"], (hash_offsets(enc), enc["offsets"])
    params = {k: arr(v) for k, v in inputs["params"].items()}
    pts = arr(inputs["points"])
    d_out = arr(inputs["d_out"])
    f = ENCODERS[enc["kind"]]
    out = {"encoding": np.array([f(enc, params, p) for p in pts]).real}
    for name, value in params.items():
        grad = np.zeros(value.size)
        for j in range(value.size):
            pc = {k: v.astype(complex) for k, v in params.items()}
            pc[name].reshape(-1)[j] += 1j * H
            grad[j] = loss(enc, pc, pts, d_out).imag / H
        out["d_" + name] = grad.reshape(value.shape)
    gx = np.zeros(pts.size)
    for j in range(pts.size):
        xc = pts.astype(complex)
        xc.reshape(-1)[j] += 1j * H
        gx[j] = loss(enc, params, xc, d_out).imag / H
    out["d_points"] = gx.reshape(pts.shape)
    return out


FOLDERS = ["field-frequency", "field-hash-grid", "field-tensorf-vm", "field-dense-grid"]

if __name__ == "__main__":
    sys.exit(check_folders(FOLDERS, run_case))
