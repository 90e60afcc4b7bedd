"""Shared scenes for the binding tests (all built from a seed, nothing stored)."""

import math
import os
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]

# A small cone beam (TIGRE fields, mm): 64 x 48 detector of 2 mm pixels, fx = fy = 750 px.
GEOMETRY = {
    "DSD": 1500.0,
    "DSO": 1000.0,
    "nDetector": [48, 64],
    "dDetector": [2.0, 2.0],
    "nVoxel": [32, 32, 32],
    "dVoxel": [2.0, 2.0, 2.0],
    "offOrigin": [0.0, 0.0, 0.0],
    "offDetector": [3.0, -2.0],
    "mode": "cone",
}


def f32_exact(x):
    """float64 values that are exactly representable in float32 (so a PLY round trip and the
    f32 path read the very same numbers)."""
    return np.asarray(x, dtype=np.float32).astype(np.float64)


def scene(n, seed, extent=40.0, log_scale=(0.3, 1.6), logit=(-2.0, 4.0)):
    """n Gaussians around the rotation centre, float64 (values exact in float32)."""
    rng = np.random.default_rng(seed)
    return {
        "means": f32_exact(rng.uniform(-extent, extent, (n, 3))),
        "quats": f32_exact(rng.normal(size=(n, 4))),
        "log_scales": f32_exact(rng.uniform(*log_scale, (n, 3))),
        "opacity_logits": f32_exact(rng.uniform(*logit, n)),
        "features": f32_exact(rng.normal(scale=0.6, size=(n, 16))),
    }


def params(sc, dtype=np.float64):
    """The five parameter arrays of a scene, in `rasterize`'s argument order."""
    return [sc[k].astype(dtype) for k in ("means", "quats", "log_scales", "opacity_logits", "features")]


def look_at_camera(distance=60.0, yaw=0.35, pitch=-0.2, f=180.0, width=40, height=36):
    """A pinhole camera `distance` from the origin looking at it: (viewmat [1, 4, 4], K [1, 3, 3],
    width, height). OpenCV axes (x right, y down, z forward)."""
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    ry = np.array([[cy, 0, -sy], [0, 1, 0], [sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    rot = rx @ ry
    vm = np.eye(4)
    vm[:3, :3] = rot
    vm[:3, 3] = [0.7, -0.4, distance]
    k = np.array([[f, 0, width / 2 + 0.3], [0, f * 1.1, height / 2 - 0.6], [0, 0, 1.0]])
    return vm[None], k[None], width, height


def unispine_binary():
    """The `unispine` binary built by `cargo test --release` / `cargo build --release`."""
    p = Path(os.environ.get("UNISPINE_BIN", REPO / "target" / "release" / "unispine"))
    if not p.exists():
        pytest.skip(f"{p} not built: run `cargo build --release` (or set UNISPINE_BIN)")
    return p


def write_ply(path, sc):
    """A binary 3DGS-layout PLY with double fields: the three colour channels equal (the
    reader averages them, exactly for float32-exact values), 15 rest coefficients each."""
    n = len(sc["means"])
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{i}" for i in range(45)]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    f = sc["features"]
    cols = [sc["means"], np.zeros((n, 3)), np.repeat(f[:, :1], 3, axis=1)]
    cols += [f[:, 1:]] * 3  # f_rest_{c * 15 + k - 1} = f_k for every channel c
    cols += [sc["opacity_logits"][:, None], sc["log_scales"], sc["quats"]]
    body = np.ascontiguousarray(np.concatenate(cols, axis=1), dtype="<f8")
    assert body.shape[1] == len(names)
    header = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % n
    header += "".join(f"property double {p}\n" for p in names) + "end_header\n"
    with open(path, "wb") as fh:
        fh.write(header.encode())
        fh.write(body.tobytes())
