"""The conformance cases: named, seeded scenes, each with what it stresses.

A case holds the Gaussians pre-activation (``means``, ``quats`` (w, x, y, z), ``log_scales``,
``opacity_logits``, ``features`` [N, 16]; exactly representable in float32 except in the
golden-file cases, which keep their float64 inputs; a float32 run rounds them and its
reference reads the rounded values), one camera in gsplat's convention
(``viewmats`` [1, 4, 4] world-to-camera, ``Ks`` [1, 3, 3], ``width``, ``height``,
``camera_model`` 'pinhole' (cone beam) or 'ortho' (parallel beam)), the colour model
(``color_mode``, ``active_features``), ``background`` and the upstream gradient ``d_image``
[1, H, W] of the loss L = sum(d_image * image). Nothing is stored: every case is rebuilt from
its seed.
"""

import math

import numpy as np

GROUPS = ("means", "quats", "log_scales", "opacity_logits", "features")


# Cases with their own float32 tolerance (float64 is the same for every case), from the worst
# float32 errors measured on the torch bridge and gsplat's reference (docs/conformance.md):
# - golden-cone-cutoffs sits on the hard decisions on purpose (alpha at 1/255 and at the clamp,
#   T at the stop); float32 rounding flips some of them: image rel-L2 4.8e-4, max 7.9e-3;
# - near-plane has depths down to 0.005 (Sigma2D ~ 1/z^2, conditioned like 1e8): gradient rel-L2
#   up to 4.2e-4.
FLOAT32_TOLERANCE = {
    "golden-cone-cutoffs": {"rel_l2": 1e-3, "max": 2e-2},
    "near-plane": {"rel_l2": 1e-3, "max": 1e-3},
}


def f32(x):
    """float64 values exactly representable in float32."""
    return np.asarray(x, dtype=np.float32).astype(np.float64)


def look_at(distance=60.0, yaw=0.35, pitch=-0.2, f=180.0, width=64, height=48, cx=None,
            cy=None, aspect=1.1):
    """A camera ``distance`` from the origin looking at it (OpenCV axes): viewmat [1, 4, 4],
    K [1, 3, 3], width, height."""
    c_, s_ = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    ry = np.array([[c_, 0, -s_], [0, 1, 0], [s_, 0, c_]])
    rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    vm = np.eye(4)
    vm[:3, :3] = rx @ ry
    vm[:3, 3] = [0.7, -0.4, distance]
    cx = width / 2 + 0.3 if cx is None else cx
    cy = height / 2 - 0.6 if cy is None else cy
    k = np.array([[f, 0, cx], [0, f * aspect, cy], [0, 0, 1.0]])
    return vm[None], k[None], width, height


def geometry_camera(geo, angle):
    """The viewmat / K of a TIGRE geometry at ``angle`` (the library's `Camera::new`: source
    at (DSO cos a, DSO sin a, 0), pixel centres at +0.5, cx = W/2 - offU/du)."""
    s, c = math.sin(angle), math.cos(angle)
    rot = np.array([[-s, c, 0.0], [0.0, 0.0, -1.0], [-c, -s, 0.0]])
    centre = np.array([geo["DSO"] * c, geo["DSO"] * s, 0.0])
    h, w = (int(x) for x in geo["nDetector"])
    dv, du = geo["dDetector"]
    off = geo.get("offDetector", [0.0, 0.0])
    vm = np.eye(4)
    vm[:3, :3] = rot
    vm[:3, 3] = -rot @ centre
    parallel = geo.get("mode", "cone") == "parallel"
    fx, fy = (1.0 / du, 1.0 / dv) if parallel else (geo["DSD"] / du, geo["DSD"] / dv)
    k = np.array([[fx, 0, w / 2 - off[0] / du], [0, fy, h / 2 - off[1] / dv], [0, 0, 1.0]])
    return vm[None], k[None], w, h, ("ortho" if parallel else "pinhole")


def _cam_points(vm, k, targets):
    """World points whose camera-space coordinates put them at pixel (u, v) and depth z, for
    rows (u, v, z) of ``targets`` (pinhole)."""
    rot, t = vm[0, :3, :3], vm[0, :3, 3]
    fx, fy, cx, cy = k[0, 0, 0], k[0, 1, 1], k[0, 0, 2], k[0, 1, 2]
    out = []
    for u, v, z in targets:
        pc = np.array([(u - cx) * z / fx, (v - cy) * z / fy, z])
        out.append(rot.T @ (pc - t))
    return np.array(out)


def _random(rng, n, extent, log_scale, logit):
    return {
        "means": rng.uniform(-extent, extent, (n, 3)),
        "quats": rng.normal(size=(n, 4)),
        "log_scales": rng.uniform(*log_scale, (n, 3)),
        "opacity_logits": rng.uniform(*logit, n),
        "features": rng.normal(scale=0.6, size=(n, 16)),
    }


def _finish(name, stresses, params, cam, seed, color_mode="rirf-paper", active=16,
            background=0.0, golden=None):
    vm, k, w, h = cam[:4]
    model = cam[4] if len(cam) > 4 else "pinhole"
    rng = np.random.default_rng(10_000 + seed)
    case = {
        "name": name,
        "stresses": stresses,
        "params": {g: (np.asarray(params[g], dtype=np.float64) if golden is not None
                       else f32(params[g])) for g in GROUPS},
        "viewmats": vm,
        "Ks": k,
        "width": int(w),
        "height": int(h),
        "camera_model": model,
        "color_mode": color_mode,
        "active_features": int(active),
        "background": float(background),
        "d_image": f32(rng.normal(size=(1, h, w))),
        "seed": seed,
    }
    if golden is not None:
        case["golden"] = golden
    if name in FLOAT32_TOLERANCE:
        case["tolerance_float32"] = FLOAT32_TOLERANCE[name]
    return case


def _golden_cases():
    from .. import golden_cases
    out = []
    for gc in golden_cases("eq04-05-render"):
        inp = gc["inputs"]
        vm, k, w, h, model = geometry_camera(inp["geometry"], float(inp["angle"]))
        params = {g: inp[g] for g in GROUPS}
        c = _finish("golden-" + gc["name"], "the golden file eq04-05-render/" + gc["name"]
                    + ".json: " + gc["description"].split(".")[0], params,
                    (vm, k, w, h, model), 0, inp["color_mode"], inp["active_features"],
                    inp["background"], golden={"outputs": gc["outputs"],
                                               "tolerance": gc["tolerance"]})
        c["d_image"] = np.asarray(inp["d_image"], dtype=np.float64)[None]
        out.append(c)
    return out


def _random_case(name, n, seed):
    rng = np.random.default_rng(seed)
    p = _random(rng, n, 9.0, (-0.7, 0.6), (-2.5, 5.0))
    return _finish(name, f"{n} random Gaussians (density)", p, look_at(), seed,
                   background=0.1)


def _tile_straddle(seed=7):
    rng = np.random.default_rng(seed)
    cam = look_at(cx=32.0, cy=24.0)
    targets = []
    for u in (16.0, 32.0, 48.0, 15.5, 32.5):
        for v in (16.0, 32.0, 16.5):
            targets.append((u + rng.uniform(-0.01, 0.01), v, rng.uniform(55, 65)))
    n = len(targets)
    p = _random(rng, n, 1.0, (-2.2, -1.2), (0.0, 4.0))
    p["means"] = _cam_points(cam[0], cam[1], targets)
    return _finish("tile-straddle", "means on 16-pixel tile boundaries, tails cut by the "
                   "tile rectangle", p, cam, seed)


def _near_plane(seed=11):
    rng = np.random.default_rng(seed)
    cam = look_at(cx=32.0, cy=24.0)
    z = [0.005, 0.05, 0.1, 0.15, 0.19, 0.3, 0.6, -0.5, -5.0, -60.0, 40.0, 60.0]
    targets = [(rng.uniform(20, 44), rng.uniform(14, 34), zz) for zz in z]
    p = _random(rng, len(z), 1.0, (-4.5, -3.5), (-1.0, 3.0))
    p["means"] = _cam_points(cam[0], cam[1], targets)
    p["log_scales"][-2:] = rng.uniform(0.0, 0.5, (2, 3))
    return _finish("near-plane", "depths between 0.01 and 0.2 (gsplat draws them, 3DGS "
                   "culls them), at and behind the camera", p, cam, seed)


def _degenerate(seed=13):
    rng = np.random.default_rng(seed)
    cam = look_at(cx=32.0, cy=24.0)
    targets = [(32, 24, 60), (20, 30, 58), (44, 18, 62), (28, 10, 61), (40, 40, 59),
               (-40, 24, 60.3), (110, 20, 60.6), (32, -30, 60.9), (30, 85, 61.2)]
    p = _random(rng, len(targets), 1.0, (-0.5, 0.5), (0.0, 3.0))
    p["means"] = _cam_points(cam[0], cam[1], targets)
    p["log_scales"][0] = [-9.0, -9.0, -9.0]     # tiny: Sigma2D = eps2d I
    p["log_scales"][1] = [1.6, -7.0, -7.0]      # needle
    p["log_scales"][2] = [1.2, 1.1, -8.0]       # flat disc
    p["log_scales"][3] = [2.0, -3.0, -1.0]
    p["log_scales"][4] = [-6.0, 1.5, -6.0]
    p["log_scales"][5:] = [[2.6, 2.4, 2.5]] * 4  # beyond the Jacobian limits, reaching in
    p["quats"][0] = [1.0, 0.0, 0.0, 0.0]
    return _finish("degenerate-anisotropic", "tiny, needle and flat covariances; means beyond "
                   "the Jacobian clamp (x/z past 1.3 tan(fov/2)) reaching into the image",
                   p, cam, seed)


def _alpha_clamp(seed=17):
    rng = np.random.default_rng(seed)
    cam = look_at(cx=32.0, cy=24.0)
    # Means on pixel centres (G = 1 there): o G above 0.999 at the centre pixel, above 0.99 in
    # a ring around it, for o = 0.9995 and 0.99995; two below both clamps.
    cols = [8, 24, 40, 56, 8, 24, 40, 56]
    rows = [10, 10, 10, 10, 34, 34, 34, 34]
    targets = [(c + 0.5, r + 0.5, 50.0 + 1.3 * i) for i, (c, r) in enumerate(zip(cols, rows))]
    p = _random(rng, 8, 1.0, (0.6, 0.9), (0.0, 1.0))
    p["opacity_logits"] = np.array([7.6, 9.9, 7.6, 9.9, 5.3, 7.6, 3.0, 1.0])
    p["quats"][:] = [1.0, 0.0, 0.0, 0.0]
    p["means"] = _cam_points(cam[0], cam[1], targets)
    return _finish("alpha-clamp", "opacity at and above both alpha clamps (0.99 and 0.999): "
                   "means on pixel centres, o G > 0.999 there and > 0.99 around", p, cam, seed,
                   background=0.2)


def _beyond_3_sigma(seed=19):
    rng = np.random.default_rng(seed)
    cam = look_at(cx=32.0, cy=24.0, aspect=1.0, distance=60.0)
    # Round splats of about 10 px sigma, opacity 0.99, 32 px left of a tile boundary: the
    # 3-sigma rectangle ends at the boundary, the 3.33-sigma one takes the next tile, whose
    # first column (3.25 sigma) has alpha ~ 0.005 > 1/255.
    targets = [(16.0, 24.0, 60.0), (47.5, 8.0, 61.0)]
    p = _random(rng, 2, 1.0, (1.2, 1.2), (4.6, 4.6))
    p["log_scales"][0] = np.log(np.array([10.0, 10.3, 9.8]) * 60.0 / 180.0)
    p["log_scales"][1] = np.log(np.array([9.0, 8.8, 9.2]) * 61.0 / 180.0)
    p["means"] = _cam_points(cam[0], cam[1], targets)
    return _finish("beyond-3-sigma", "round splats of ~10 px sigma, opacity 0.99, placed so "
                   "that the tile rectangle of 3 sigma stops at a tile boundary and that of "
                   "3.33 sigma does not (alpha ~ 0.005 at 3.25 sigma)", p, cam, seed)


def _saturating(seed=23):
    rng = np.random.default_rng(seed)
    cam = look_at(cx=32.0, cy=24.0)
    n = 40
    targets = [(rng.uniform(24, 40), rng.uniform(16, 32), 50 + 0.5 * i) for i in range(n)]
    p = _random(rng, n, 1.0, (-0.3, 0.3), (2.5, 6.0))
    p["means"] = _cam_points(cam[0], cam[1], targets)
    return _finish("saturating", "40 stacked opaque Gaussians: the transmittance stop "
                   "(T < 1e-4) ends most pixels", p, cam, seed, background=0.3)


def _principal_point(seed=29):
    rng = np.random.default_rng(seed)
    cam = look_at(cx=14.0, cy=35.0)
    targets = [(rng.uniform(-25, 90), rng.uniform(-20, 70), rng.uniform(40, 70))
               for _ in range(30)]
    p = _random(rng, 30, 1.0, (0.2, 1.3), (-1.0, 4.0))
    p["means"] = _cam_points(cam[0], cam[1], targets)
    return _finish("principal-point", "principal point far from the image centre (cx = 14, "
                   "cy = 35 on 64 x 48): asymmetric Jacobian limits", p, cam, seed)


def _parallel(seed=31):
    rng = np.random.default_rng(seed)
    vm, k, w, h = look_at(distance=100.0, f=1.5, cx=33.0, cy=23.0, aspect=1.0)
    p = _random(rng, 50, 18.0, (-0.2, 1.2), (-2.0, 4.0))
    return _finish("parallel-beam", "parallel beam (camera_model 'ortho', J = diag(fx, fy))",
                   p, (vm, k, w, h, "ortho"), seed, background=0.05)


def _colour(name, mode, active, seed):
    rng = np.random.default_rng(seed)
    p = _random(rng, 40, 9.0, (-0.7, 0.6), (-1.0, 4.0))
    return _finish(name, f"colour model {mode}, {active} active features", p, look_at(),
                   seed, color_mode=mode, active=active, background=0.1)


def all_cases():
    """Every case, in a fixed order."""
    return _golden_cases() + [
        _random_case("random-sparse", 16, 1),
        _random_case("random-medium", 64, 2),
        _random_case("random-dense", 200, 3),
        _tile_straddle(), _near_plane(), _degenerate(), _alpha_clamp(), _beyond_3_sigma(),
        _saturating(), _principal_point(), _parallel(),
        _colour("sh-degree-3", "sh", 16, 37),
        _colour("sh-degree-1", "sh", 4, 41),
        _colour("rirf-xgaussian", "rirf-xgaussian", 9, 43),
        _colour("rirf-paper", "rirf-paper", 16, 47),
    ]


def case_names():
    return [c["name"] for c in all_cases()]


def select(names=None):
    """The cases named in ``names`` (None or ['all']: every case); unknown names raise."""
    cases = all_cases()
    if names is None or list(names) == ["all"]:
        return cases
    by = {c["name"]: c for c in cases}
    unknown = [n for n in names if n not in by]
    if unknown:
        raise ValueError(f"unknown cases {unknown}; cases: {list(by)}")
    return [by[n] for n in names]
