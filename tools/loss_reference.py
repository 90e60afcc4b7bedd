#!/usr/bin/env python3
"""Independent numpy reference for the golden files of Eqs. (6)-(9) (SPWM and the losses).

Recomputes the outputs of every case in golden/eq06-spwm-prior, golden/eq07-spwm-weights,
golden/eq08-hybrid-loss and golden/eq09-weighted-charbonnier from the case's inputs and compares
them with the stored outputs within the case's tolerance (|ref - golden| <= abs + rel |golden|).
Exits non-zero on any mismatch.

Written from the equations and the description of the UniSpine-GS code (utils/loss_utils.py,
train.py), not from the Rust code, and by other means:
- every filter is a direct 2D cross-correlation of the zero-padded image (numpy.pad +
  sliding_window_view) with the full 2D kernel (Sobel 3x3 literal; Gaussian outer products),
  where the Rust code runs separable 1D passes;
- SSIM uses the dense (N x N) matrix of the 11x11 windowed correlation;
- tau is numpy.quantile (method "linear");
- every gradient is the complex-step derivative Im f(x + i h e_k) / h (h = 1e-30, all pixels at
  once), exact to rounding and independent of any hand-derived backward formula. L1 is written
  as e * sign(Re e) (equal to |e| on the reals), whose complex step is the subgradient sign(e)
  with 0 at e = 0.

Usage: python3 tools/loss_reference.py   (from the repository root)
"""
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from golden_io import arr, check_folders  # noqa: E402
from numpy.lib.stride_tricks import sliding_window_view

FOLDERS = ["eq06-spwm-prior", "eq07-spwm-weights", "eq08-hybrid-loss", "eq09-weighted-charbonnier"]

# The paper / code constants, written here from their upstream sources (not from the Rust code),
# so that a changed Rust default fails the golden tests: the cases in PINNED must carry exactly
# these values in their inputs, and tests/loss/golden.rs checks that the Rust defaults
# serialise to those inputs.
# SPWM: UniSpine-GS (github.com/orangeisland66/UniSpine-GS) config/example.yaml (attn_alpha,
# attn_hf_lambda, attn_blur_kernel, attn_blur_sigma, attn_adaptive_gate, attn_gate_quantile,
# attn_gate_thresh, attn_warmup_start, attn_warmup_iters) and train.py (tau clamped to
# [0, 0.98]; the gate is a clamped linear ramp). gate_temperature is ours (only used by the
# sigmoid gate, which the code does not have).
SPWM_PAPER = {
    "alpha": 0.8, "hf_lambda": 0.5, "blur_kernel": 3, "blur_sigma": 1.5, "adaptive_gate": True,
    "quantile": 0.85, "tau_max": 0.98, "fixed_tau": 0.4, "warmup_start": 2000,
    "warmup_iters": 5000, "gate": "clamped-linear", "gate_temperature": 0.05,
}
# Loss, Eqs. (8)-(9): lambda_dssim 0.2 (config/example.yaml), Charbonnier eps 1e-3 (train.py
# argparse default charb_eps) and delta 1e-6 (utils/loss_utils.py, hard-coded).
LOSS_PAPER = {"lambda_dssim": 0.2, "charbonnier_eps": 1e-3, "delta": 1e-6}
PINNED = {
    ("eq06-spwm-prior", "structured"): {"spwm": SPWM_PAPER},
    ("eq07-spwm-weights", "warmup"): {"spwm": SPWM_PAPER},
    ("eq08-hybrid-loss", "weighted-charbonnier-dssim"):
        {"loss": dict(LOSS_PAPER, data_term="weighted-charbonnier")},
    ("eq08-hybrid-loss", "l1-dssim"): {"loss": dict(LOSS_PAPER, data_term="l1")},
    ("eq08-hybrid-loss", "charbonnier-dssim"): {"loss": dict(LOSS_PAPER, data_term="charbonnier")},
    ("eq09-weighted-charbonnier", "spwm-weights"):
        {"eps": LOSS_PAPER["charbonnier_eps"], "delta": LOSS_PAPER["delta"]},
}


def check_pinned(folder, stem, inputs):
    """Raise if a pinned case's inputs differ from the paper / code constants."""
    for key, want in PINNED.get((folder, stem), {}).items():
        if inputs.get(key) != want:
            raise ValueError(f"{folder}/{stem}.json: inputs.{key} = {inputs.get(key)} differs from "
                             f"the paper / code constants {want}")


SOBEL_X = np.array([[-1.0, 0.0, 1.0], [-2.0, 0.0, 2.0], [-1.0, 0.0, 1.0]])
SOBEL_Y = np.array([[-1.0, -2.0, -1.0], [0.0, 0.0, 0.0], [1.0, 2.0, 1.0]])
C1 = 0.01 ** 2
C2 = 0.03 ** 2
STEP = 1e-30


def correlate2d(img, kernel):
    """Same-size 2D cross-correlation with zero padding kernel.shape // 2 (torch conv2d)."""
    kh, kw = kernel.shape
    padded = np.pad(img, ((kh // 2, kh // 2), (kw // 2, kw // 2)))
    windows = sliding_window_view(padded, (kh, kw))
    return np.einsum("ijab,ab->ij", windows, kernel)


def gauss1d(size, sigma, norm_eps):
    c = np.arange(size, dtype=np.float64) - size // 2
    g = np.exp(-(c ** 2) / (2.0 * sigma * sigma))
    return g / (g.sum() + norm_eps)


# ---------------------------------------------------------------- Eqs. (6)-(7)

def spwm(gt, cfg):
    gx = correlate2d(gt, SOBEL_X)
    gy = correlate2d(gt, SOBEL_Y)
    edge = np.sqrt(gx * gx + gy * gy + 1e-6)
    k = cfg["blur_kernel"] + (1 if cfg["blur_kernel"] % 2 == 0 else 0)
    g = gauss1d(k, cfg["blur_sigma"], 1e-12)
    high = np.abs(gt - correlate2d(gt, np.outer(g, g)))
    raw = edge + cfg["hf_lambda"] * high
    att = np.clip((raw - raw.min()) / (raw.max() - raw.min() + 1e-6), 0.0, 1.0)
    if cfg["adaptive_gate"]:
        tau = float(np.clip(np.quantile(att.ravel(), cfg["quantile"], method="linear"), 0.0,
                            cfg["tau_max"]))
    else:
        tau = float(cfg["fixed_tau"])
    if cfg["gate"] == "clamped-linear":
        gate = np.clip((att - tau) / (1.0 - tau + 1e-6), 0.0, 1.0)
    elif cfg["gate"] == "sigmoid":
        gate = 1.0 / (1.0 + np.exp(-(att - tau) / cfg["gate_temperature"]))
    else:
        raise ValueError(f"unknown gate {cfg['gate']}")
    return {"edge": edge, "high": high, "attention": att, "tau": np.float64(tau), "gate": gate,
            "prior": gate * att}


def warmup(t, cfg):
    if t <= cfg["warmup_start"]:
        return 0.0
    return min(1.0, (t - cfg["warmup_start"]) / max(1, cfg["warmup_iters"]))


# ---------------------------------------------------------------- Eqs. (8)-(9)

def window_matrix(h, w):
    """Dense N x N matrix M with (M x)[p] = sum_q win(q - p) x[q] (11x11, zero padding 5)."""
    g = gauss1d(11, 1.5, 0.0)
    win = np.outer(g, g)
    n = h * w
    m = np.zeros((n, n))
    for r in range(h):
        for c in range(w):
            for a in range(11):
                for b in range(11):
                    rr, cc = r + a - 5, c + b - 5
                    if 0 <= rr < h and 0 <= cc < w:
                        m[r * w + c, rr * w + cc] = win[a, b]
    return m


def ssim_batch(x, y, m):
    """Mean SSIM of each column of x (N x B, maybe complex) against y (N)."""
    y = y[:, None]
    mu1, mu2 = m @ x, m @ y
    s11 = m @ (x * x) - mu1 * mu1
    s22 = m @ (y * y) - mu2 * mu2
    s12 = m @ (x * y) - mu1 * mu2
    smap = ((2 * mu1 * mu2 + C1) * (2 * s12 + C2)) / ((mu1 ** 2 + mu2 ** 2 + C1) * (s11 + s22 + C2))
    return smap.mean(axis=0)


def data_term(e, w, kind, eps, delta):
    """Data term of each column of the residuals e (N x B, maybe complex)."""
    if kind == "l1":
        return (e * np.sign(e.real)).mean(axis=0)
    rho = np.sqrt(e * e + eps * eps)
    if kind == "charbonnier":
        return rho.mean(axis=0)
    if kind == "weighted-charbonnier":
        w = np.ones(e.shape[0]) if w is None else w
        return (w[:, None] * rho).sum(axis=0) / (w.sum() + delta)
    raise ValueError(f"unknown data term {kind}")


def value_and_grad(f, x):
    """f maps an N x B batch to B values; returns f(x) and the complex-step gradient."""
    n = x.size
    value = f(x[:, None].astype(np.complex128))[0].real
    batch = x[:, None] + 1j * STEP * np.eye(n)
    grad = f(batch).imag / STEP
    return value, grad


def hybrid(render, gt, w, lc):
    h, wd = render.shape
    x, y = render.ravel(), gt.ravel()
    wv = None if w is None else w.ravel()
    m = window_matrix(h, wd)
    lam = lc["lambda_dssim"]

    def parts(xb):
        d = data_term(xb - y[:, None], wv, lc["data_term"], lc["charbonnier_eps"], lc["delta"])
        s = ssim_batch(xb, y, m)
        return d, s

    def total(xb):
        d, s = parts(xb)
        return (1 - lam) * d + lam * (1 - s)

    d, s = parts(x[:, None].astype(np.complex128))
    t, g = value_and_grad(total, x)
    return {"total": np.float64(t), "data": np.float64(d[0].real), "ssim": np.float64(s[0].real),
            "grad": g.reshape(h, wd)}


# ---------------------------------------------------------------- cases

def run_case(folder, inputs):
    if folder == "eq06-spwm-prior":
        return spwm(arr(inputs["gt"]), inputs["spwm"])
    if folder == "eq07-spwm-weights":
        cfg = inputs["spwm"]
        prior = spwm(arr(inputs["gt"]), cfg)["prior"]
        its = inputs["iterations"]
        r = np.array([warmup(t, cfg) for t in its])
        return {"r": r, "weights": np.stack([1.0 + cfg["alpha"] * rt * prior for rt in r])}
    if folder == "eq08-hybrid-loss":
        w = arr(inputs["weights"]) if "weights" in inputs else None
        return hybrid(arr(inputs["render"]), arr(inputs["gt"]), w, inputs["loss"])
    if folder == "eq09-weighted-charbonnier":
        render, gt = arr(inputs["render"]), arr(inputs["gt"])
        w = arr(inputs["weights"]).ravel() if "weights" in inputs else None
        y = gt.ravel()
        f = lambda xb: data_term(xb - y[:, None], w, "weighted-charbonnier", inputs["eps"],
                                 inputs["delta"])
        v, g = value_and_grad(f, render.ravel())
        return {"loss": np.float64(v), "grad": g.reshape(render.shape)}
    raise ValueError(f"unknown folder {folder}")


def pinned_and_run(folder, stem, inputs):
    check_pinned(folder, stem, inputs)
    return run_case(folder, inputs)


def main():
    missing = [k for k in PINNED if not (pathlib.Path(__file__).resolve().parent.parent / "golden"
                                          / k[0] / f"{k[1]}.json").exists()]
    if missing:
        print(f"FAIL pinned cases missing: {missing}")
        return 1
    try:
        return check_folders(FOLDERS, pinned_and_run)
    except ValueError as e:
        print(f"FAIL {e}")
        return 1


if __name__ == "__main__":
    sys.exit(main())
