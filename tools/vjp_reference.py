#!/usr/bin/env python3
"""Independent numpy check of the backward golden files of Eqs. (1)-(3).

For every case of golden/eq01-covariance-vjp, golden/eq02-rirf-vjp and
golden/eq03-projection-vjp: L = sum(upstream * forward(inputs)) is evaluated by a numpy forward
written here to accept complex numbers, and every input gradient is its complex-step derivative
dL/dx_j = Im L(x + i h e_j) / h with h = 1e-30 (exact to rounding, no cancellation; no
hand-written backward). Hard decisions are taken on the real parts, at the unperturbed point:
culling (from tools/golden_reference.py's real projection), the clamp of x/z and y/z inside the
Jacobian (a clamped coordinate is a constant), and max(0, .) of the intensity.
Compares with the stored outputs within each file's tolerance; exits non-zero on a mismatch.

Usage: python3 tools/vjp_reference.py   (from the repository root)
"""
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from golden_io import arr, check_folders  # noqa: E402
from golden_reference import LAMBDA, camera, project, sh_basis  # noqa: E402

H = 1e-30


def rotation(q):
    """Rotation matrix of q / |q| (q = (w, x, y, z)), complex-safe: |q| = sqrt(sum q^2)."""
    w, x, y, z = q / np.sqrt(np.sum(q * q))
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def covariance(log_scale, q):
    """Eq. (1), complex-safe."""
    m = rotation(q) * np.exp(log_scale)[None, :]
    return m @ m.T


def clamp_real(v, lo, hi):
    """clamp on the real part; a clamped value is the real constant (zero derivative)."""
    if v.real < lo:
        return lo
    if v.real > hi:
        return hi
    return v


def intensity(mode, k, f, mean=None, centre=None):
    """Eq. (2) / SH colour, complex-safe; max(0, .) decided on the real part."""
    if mode == "sh":
        d = mean - centre
        d = d / np.sqrt(np.sum(d * d))
        s = 0.5 + np.sum(sh_basis(d)[:k] * f[:k])
        return s if s.real >= 0 else 0.0 * s
    s = np.sum(LAMBDA[:k] * f[:k])
    if mode == "rirf-paper":
        return 1.0 / (1.0 + np.exp(-s))
    return 0.5 + s if (0.5 + s).real >= 0 else 0.0 * s


def projection(cam, mean, log_scale, q):
    """Eq. (3) for a visible Gaussian, complex-safe: (mean2d, conic (A, B, C))."""
    t = cam["rot"] @ (mean - cam["centre"])
    x, y, z = t
    if cam["mode"] == "parallel":
        mean2d = np.array([x / cam["du"] + cam["cx"], y / cam["dv"] + cam["cy"]])
        jac = np.array([[1.0 / cam["du"], 0.0, 0.0], [0.0, 1.0 / cam["dv"], 0.0]], dtype=complex)
    else:
        fx, fy = cam["fx"], cam["fy"]
        mean2d = np.array([fx * x / z + cam["cx"], fy * y / z + cam["cy"]])
        lim_x, lim_y = 1.3 * cam["W"] / (2.0 * fx), 1.3 * cam["H"] / (2.0 * fy)
        xz = clamp_real(x / z, -lim_x, lim_x)
        yz = clamp_real(y / z, -lim_y, lim_y)
        jac = np.array([[fx / z, 0.0, -fx * xz / z], [0.0, fy / z, -fy * yz / z]])
    cov2d = jac @ cam["rot"] @ covariance(log_scale, q) @ cam["rot"].T @ jac.T
    a, b, c = cov2d[0, 0] + 0.3, cov2d[0, 1], cov2d[1, 1] + 0.3
    det = a * c - b * b
    return mean2d, np.array([c / det, -b / det, a / det])


def complex_step(loss, inputs):
    """Gradient of the real scalar loss(*inputs) with respect to every input array."""
    grads = []
    for k, x in enumerate(inputs):
        g = np.zeros(x.shape)
        for j in np.ndindex(x.shape):
            xs = [np.asarray(v, dtype=complex) for v in inputs]
            xs[k][j] += 1j * H
            g[j] = loss(*xs).imag / H
        grads.append(g)
    return grads


def run_case(folder, stem, inp):
    if folder == "eq01-covariance-vjp":
        ls, qs, g = arr(inp["log_scales"]), arr(inp["quats"]), arr(inp["d_covariance"])
        dl, dq = [], []
        for i in range(len(ls)):
            a, b = complex_step(lambda l, q: np.sum(g[i] * covariance(l, q)), [ls[i], qs[i]])
            dl.append(a)
            dq.append(b)
        return {"d_log_scales": np.array(dl), "d_quats": np.array(dq)}
    if folder == "eq02-rirf-vjp":
        f, gi, mode = arr(inp["features"]), arr(inp["d_intensity"]), inp["color_mode"]
        means = arr(inp["means"]) if mode == "sh" else np.zeros((len(f), 3))
        centre = np.asarray(inp.get("camera_centre", [0.0, 0.0, 0.0]))
        df = np.zeros((len(inp["active_features"]), len(f), 16))
        dm = np.zeros((len(inp["active_features"]), len(f), 3))
        for j, k in enumerate(inp["active_features"]):
            for i in range(len(f)):
                df[j, i], dm[j, i] = complex_step(
                    lambda ff, m: gi[j, i] * intensity(mode, k, ff, m, centre), [f[i], means[i]])
        return {"d_features": df, "d_means": dm} if mode == "sh" else {"d_features": df}
    if folder == "eq03-projection-vjp":
        cam = camera(inp["geometry"], inp["angle"])
        means, ls, qs = arr(inp["means"]), arr(inp["log_scales"]), arr(inp["quats"])
        gm, gc = arr(inp["d_mean2d"]), arr(inp["d_conic"])
        out = {k: np.zeros((len(means), n)) for k, n in
               [("d_means", 3), ("d_log_scales", 3), ("d_quats", 4)]}
        for i in range(len(means)):
            if project(cam, means[i], ls[i], qs[i])[2] == 0:
                continue  # culled: zero gradient
            def loss(m, l, q):
                m2, co = projection(cam, m, l, q)
                return np.sum(gm[i] * m2) + np.sum(gc[i] * co)
            g = complex_step(loss, [means[i], ls[i], qs[i]])
            for key, v in zip(["d_means", "d_log_scales", "d_quats"], g):
                out[key][i] = v
        return out
    raise ValueError(f"unknown folder {folder}")


def main():
    return check_folders(["eq01-covariance-vjp", "eq02-rirf-vjp", "eq03-projection-vjp"],
                         run_case)


if __name__ == "__main__":
    sys.exit(main())
