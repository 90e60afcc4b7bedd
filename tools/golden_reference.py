#!/usr/bin/env python3
"""Independent numpy reference for the golden files of Eqs. (1)-(3).

Recomputes the outputs of every case in golden/eq01-covariance, golden/eq02-rirf and
golden/eq03-projection from the case's inputs and compares them with the stored outputs within
the case's tolerance (|ref - golden| <= abs + rel |golden|). Exits non-zero on any mismatch.

Written from the equations, not from the Rust code:
- rotation from the unit quaternion by Rodrigues' formula R = I + sin(th) K + (1 - cos(th)) K^2
  (axis-angle), not the polynomial quaternion matrix;
- SH constants from their closed forms (sqrt(k / pi) / m);
- the camera (pose, intrinsics, principal point) built from the TIGRE geometry following the
  NAF convention written in `src/geometry.rs` and `paper_notes.md` (Conventions);
- Sigma2D eigenvalues from the half-difference form, the Jacobian from the perspective map's
  partial derivatives, the conic by numpy's matrix inverse.

Usage: python3 tools/golden_reference.py   (from the repository root)
"""
import math
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from golden_io import arr, check_folders  # noqa: E402


# Real SH constants with the signs of the 3DGS evaluation order.
PI = math.pi
C0 = 1.0 / (2.0 * math.sqrt(PI))
C1 = math.sqrt(3.0 / (4.0 * PI))
C2 = [
    math.sqrt(15.0 / PI) / 2.0,
    -math.sqrt(15.0 / PI) / 2.0,
    math.sqrt(5.0 / PI) / 4.0,
    -math.sqrt(15.0 / PI) / 2.0,
    math.sqrt(15.0 / PI) / 4.0,
]
C3 = [
    -math.sqrt(35.0 / (2.0 * PI)) / 4.0,
    math.sqrt(105.0 / PI) / 2.0,
    -math.sqrt(21.0 / (2.0 * PI)) / 4.0,
    math.sqrt(7.0 / PI) / 4.0,
    -math.sqrt(21.0 / (2.0 * PI)) / 4.0,
    math.sqrt(105.0 / PI) / 4.0,
    -math.sqrt(35.0 / (2.0 * PI)) / 4.0,
]
LAMBDA = np.array([C0, -C1, C1, -C1] + C2 + C3)


def rotation(q):
    """Rotation of the quaternion q = (w, x, y, z) (normalised here) by Rodrigues' formula."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q)
    w, v = q[0], q[1:]
    s = np.linalg.norm(v)
    if s == 0.0:
        return np.eye(3)
    axis = v / s
    theta = 2.0 * math.atan2(s, w)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(theta) * k + (1.0 - math.cos(theta)) * (k @ k)


def covariance(log_scale, q):
    """Eq. (1)."""
    r = rotation(q)
    s2 = np.diag(np.exp(2.0 * np.asarray(log_scale)))
    return r @ s2 @ r.T


def sh_basis(d):
    x, y, z = d
    return np.array([
        C0,
        -C1 * y, C1 * z, -C1 * x,
        C2[0] * x * y, C2[1] * y * z, C2[2] * (2 * z * z - x * x - y * y), C2[3] * x * z,
        C2[4] * (x * x - y * y),
        C3[0] * y * (3 * x * x - y * y), C3[1] * x * y * z, C3[2] * y * (4 * z * z - x * x - y * y),
        C3[3] * z * (2 * z * z - 3 * x * x - 3 * y * y), C3[4] * x * (4 * z * z - x * x - y * y),
        C3[5] * z * (x * x - y * y), C3[6] * x * (x * x - 3 * y * y),
    ])


def camera(geo, angle):
    """NAF / X-Gaussian pose: source at DSO (cos, sin, 0); axes x = (-sin, cos, 0),
    y = (0, 0, -1), z = (-cos, -sin, 0); pixel (c, r) centred at (c + 0.5, r + 0.5);
    detector coordinate u = (c + 0.5 - W/2) du + offU lies at u_pix = fx X/Z + cx."""
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[-s, c, 0.0], [0.0, 0.0, -1.0], [-c, -s, 0.0]])
    centre = geo["DSO"] * np.array([c, s, 0.0])
    rows, cols = geo["nDetector"]
    dv, du = geo["dDetector"]
    off_u, off_v = geo["offDetector"]
    return {
        "rot": rot, "centre": centre, "W": cols, "H": rows,
        # Cone: detector coordinate u at distance DSD -> pixel (u - offU)/du + W/2.
        "fx": geo["DSD"] / du, "fy": geo["DSD"] / dv,
        "cx": cols / 2.0 - off_u / du, "cy": rows / 2.0 - off_v / dv,
        "du": du, "dv": dv, "mode": geo.get("mode", "cone"),
    }


def project(cam, mean, log_scale, q):
    """Eq. (3) for one Gaussian: (mean2d, conic, radius, depth)."""
    t = cam["rot"] @ (np.asarray(mean) - cam["centre"])
    x, y, z = t
    culled = (np.zeros(2), np.zeros(3), 0, z)
    if not z > 0.2:
        return culled
    if cam["mode"] == "parallel":
        # Orthographic: detector coordinate = camera-space X, pixel = X/du + cx.
        mean2d = np.array([x / cam["du"] + cam["cx"], y / cam["dv"] + cam["cy"]])
        jac = np.array([[1.0 / cam["du"], 0.0, 0.0], [0.0, 1.0 / cam["dv"], 0.0]])
    else:
        fx, fy = cam["fx"], cam["fy"]
        mean2d = np.array([fx * x / z + cam["cx"], fy * y / z + cam["cy"]])
        # d(fx X/Z, fy Y/Z)/d(X, Y, Z), evaluated with X/Z, Y/Z limited to 1.3 tan(fov/2).
        lim_x = 1.3 * cam["W"] / (2.0 * fx)
        lim_y = 1.3 * cam["H"] / (2.0 * fy)
        xz = min(max(x / z, -lim_x), lim_x)
        yz = min(max(y / z, -lim_y), lim_y)
        jac = np.array([[fx / z, 0.0, -fx * xz / z], [0.0, fy / z, -fy * yz / z]])
    sigma_cam = cam["rot"] @ covariance(log_scale, q) @ cam["rot"].T
    cov2d = jac @ sigma_cam @ jac.T + 0.3 * np.eye(2)
    a, b, c = cov2d[0, 0], cov2d[0, 1], cov2d[1, 1]
    det = a * c - b * b
    if not det > 0.0:
        return culled
    conic_m = np.linalg.inv(cov2d)
    conic = np.array([conic_m[0, 0], 0.5 * (conic_m[0, 1] + conic_m[1, 0]), conic_m[1, 1]])
    # Largest eigenvalue, 3DGS floor 0.1 on the discriminant (mid^2 - det = ((a-c)/2)^2 + b^2).
    mid = 0.5 * (a + c)
    lam = mid + math.sqrt(max(0.1, (0.5 * (a - c)) ** 2 + b * b))
    radius = math.ceil(3.0 * math.sqrt(lam))
    u, v = mean2d
    if u + radius <= 0 or u - radius >= cam["W"] or v + radius <= 0 or v - radius >= cam["H"]:
        return culled
    return mean2d, conic, radius, z


def sigmoid(x):
    return 1.0 / (1.0 + math.exp(-x))


def run_case(folder, stem, inp):
    if folder == "eq01-covariance":
        ls, qs = arr(inp["log_scales"]), arr(inp["quats"])
        return {"covariance": np.stack([covariance(l, q) for l, q in zip(ls, qs)])}
    if folder == "eq02-rirf":
        f = arr(inp["features"])
        out = []
        for k in inp["active_features"]:
            row = []
            for i in range(f.shape[0]):
                mode = inp["color_mode"]
                if mode == "sh":
                    v = arr(inp["means"])[i] - np.asarray(inp["camera_centre"])
                    basis = sh_basis(v / np.linalg.norm(v))
                    row.append(max(0.0, 0.5 + float(basis[:k] @ f[i, :k])))
                else:
                    s = float(LAMBDA[:k] @ f[i, :k])
                    row.append(sigmoid(s) if mode == "rirf-paper" else max(0.0, 0.5 + s))
            out.append(row)
        return {"intensity": np.array(out)}
    if folder == "eq03-projection":
        cam = camera(inp["geometry"], inp["angle"])
        means, ls, qs = arr(inp["means"]), arr(inp["log_scales"]), arr(inp["quats"])
        res = [project(cam, m, l, q) for m, l, q in zip(means, ls, qs)]
        return {
            "mean2d": np.stack([r[0] for r in res]),
            "conic": np.stack([r[1] for r in res]),
            "radius": np.array([r[2] for r in res], dtype=np.float64),
            "depth": np.array([r[3] for r in res]),
        }
    raise ValueError(f"unknown folder {folder}")


def main():
    return check_folders(["eq01-covariance", "eq02-rirf", "eq03-projection"], run_case)


if __name__ == "__main__":
    sys.exit(main())
