"""`project`, `rasterize_vjp`, `loss`, `ssim`, `drr` through the bindings against the golden
files (independently checked by the numpy references in `tools/`), finite differences and a
closed form."""

import numpy as np
import pytest

import unispine
from conftest import GEOMETRY


def check(case, name, mine):
    want = np.asarray(case["outputs"][name], dtype=np.float64)
    tol = case["tolerance"]
    mine = np.asarray(mine, dtype=np.float64).reshape(want.shape)
    assert np.all(np.abs(mine - want) <= tol["abs"] + tol["rel"] * np.abs(want)), \
        (case["folder"], case["name"], name)


@pytest.mark.parametrize("case", unispine.golden_cases("eq03-projection"), ids=lambda c: c["name"])
def test_project_matches_the_eq03_goldens(case):
    inp = case["inputs"]
    n = len(inp["means"])
    p = unispine.project(inp["means"], inp["quats"], inp["log_scales"], np.zeros(n),
                         np.zeros((n, 16)), geometry=inp["geometry"], angles=inp["angle"])
    for ours, golden in [("means2d", "mean2d"), ("conics", "conic"), ("depths", "depth"),
                         ("radii", "radius")]:
        check(case, golden, p[ours][0])


@pytest.mark.parametrize("case", unispine.golden_cases("eq04-05-render"), ids=lambda c: c["name"])
def test_rasterize_vjp_matches_the_eq04_05_goldens(case):
    inp = case["inputs"]
    ps = [inp[k] for k in ("means", "quats", "log_scales", "opacity_logits", "features")]
    kw = dict(geometry=inp["geometry"], angles=inp["angle"], color_mode=inp["color_mode"],
              active_features=inp["active_features"], background=inp["background"])
    g = unispine.rasterize_vjp(*ps, d_image=inp["d_image"][None], **kw)
    check(case, "image", g["image"][0])
    for k in ("means", "quats", "log_scales", "opacity_logits", "features"):
        check(case, "d_" + k, g["d_" + k])


@pytest.mark.parametrize("case", unispine.golden_cases("eq08"), ids=lambda c: c["name"])
def test_loss_matches_the_eq08_goldens(case):
    inp = case["inputs"]
    cfg = inp["loss"]
    out = unispine.loss(inp["render"], inp["gt"], inp.get("weights"),
                        data_term=cfg["data_term"], lambda_dssim=cfg["lambda_dssim"],
                        charbonnier_eps=cfg["charbonnier_eps"], delta=cfg["delta"])
    for k in ("total", "data", "ssim", "grad"):
        check(case, k, out[k])


@pytest.mark.parametrize("case", unispine.golden_cases("eq09"), ids=lambda c: c["name"])
def test_loss_matches_the_eq09_goldens(case):
    inp = case["inputs"]
    out = unispine.loss(inp["render"], inp["gt"], inp.get("weights"), lambda_dssim=0.0,
                        charbonnier_eps=inp["eps"], delta=inp["delta"])
    check(case, "loss", out["total"])
    check(case, "grad", out["grad"])


def test_ssim_gradient_against_central_differences():
    rng = np.random.default_rng(7)
    a, b = rng.random((13, 17)), rng.random((13, 17))
    s, g = unispine.ssim(a, b)
    assert s == pytest.approx(unispine.ssim(a, b)[0]) and -1 < s < 1
    assert unispine.ssim(a, a)[0] == pytest.approx(1.0, abs=1e-12)
    h = 1e-5
    for idx in [(0, 0), (6, 8), (12, 16), (3, 11)]:
        ap, am = a.copy(), a.copy()
        ap[idx] += h
        am[idx] -= h
        fd = (unispine.ssim(ap, b)[0] - unispine.ssim(am, b)[0]) / (2 * h)
        assert abs(fd - g[idx]) <= 1e-8 * max(1.0, abs(fd)), idx
    s32, g32 = unispine.ssim(a.astype(np.float32), b.astype(np.float32))
    assert g32.dtype == np.float32 and abs(s32 - s) < 1e-5


@pytest.mark.parametrize("method", ["siddon", "trilinear"])
def test_drr_of_a_uniform_cube_is_its_chord_length(method):
    geo = dict(GEOMETRY, mode="parallel", offDetector=[0.0, 0.0])
    mu = 0.01
    vol = np.full(geo["nVoxel"], mu)
    img = unispine.drr(vol, geo, [0.0, np.pi / 2], method=method)
    assert img.shape == (2, 48, 64) and img.dtype == np.float64
    side = geo["nVoxel"][0] * geo["dVoxel"][0]          # 64 mm along every axis
    # Parallel rays along a cube axis: the central detector pixels see the full side.
    centre = img[:, 24 - 4:24 + 4, 32 - 4:32 + 4]
    assert np.allclose(centre, mu * side, rtol=1e-9), centre.ravel()[:4]
    # Outside the cube's shadow (|u| > 32 mm = 16 pixels of 2 mm): nothing.
    assert np.all(img[:, :, :10] == 0) and np.all(img[:, :, -10:] == 0)
    f = unispine.drr(np.asfortranarray(vol.astype(np.float32)), geo, 0.0, method=method)
    assert f.dtype == np.float32 and np.allclose(f[0], img[0], rtol=1e-5)


def test_golden_cases_select_folders_and_hold_the_vjp_cases():
    folders = unispine.golden_folders()
    for f in ["eq01-covariance-vjp", "eq02-rirf-vjp", "eq03-projection-vjp"]:
        assert f in folders
    assert {c["folder"] for c in unispine.golden_cases("eq03")} == {
        "eq03-projection", "eq03-projection-vjp"}
    vjp = unispine.golden_cases("eq03-projection-vjp")
    assert len(vjp) == 3 and all(c["folder"] == "eq03-projection-vjp" for c in vjp)
    case = vjp[0]
    assert case["inputs"]["d_mean2d"].shape == (len(case["inputs"]["means"]), 2)
    assert case["outputs"]["d_quats"].dtype == np.float64
    assert case["tolerance"]["abs"] > 0 and "complex step" in case["checked_by"]


@pytest.mark.parametrize("case", unispine.golden_cases("eq03-projection-vjp"),
                         ids=lambda c: c["name"])
def test_project_vjp_matches_the_eq03_vjp_goldens(case):
    inp = case["inputs"]
    n = len(inp["means"])
    g = unispine.project_vjp(inp["means"], inp["quats"], inp["log_scales"], np.zeros(n),
                             np.zeros((n, 16)), geometry=inp["geometry"], angles=inp["angle"],
                             d_means2d=inp["d_mean2d"][None], d_conics=inp["d_conic"][None])
    for k in ("d_means", "d_log_scales", "d_quats"):
        check(case, k, g[k])
    assert not g["d_features"].any() and not g["d_opacity_logits"].any()


def test_rasterize_vjp_is_composite_backward_then_project_vjp():
    """The screen-space gradients that rasterize_vjp exposes, pushed through project_vjp, give
    its parameter gradients (two cameras: summed in camera order)."""
    from conftest import params, scene
    ps = params(scene(80, seed=9))
    kw = dict(geometry=GEOMETRY, angles=[0.3, 2.0], color_mode="sh")
    d = np.random.default_rng(3).normal(size=(2, 48, 64))
    full = unispine.rasterize_vjp(*ps, d_image=d, **kw)
    staged = unispine.project_vjp(*ps, d_means2d=full["d_means2d"], d_conics=full["d_conics"],
                                  d_opacities=full["d_opacities"], d_colors=full["d_colors"],
                                  **kw)
    for k in ("means", "quats", "log_scales", "opacity_logits", "features"):
        assert np.array_equal(staged["d_" + k], full["d_" + k]), k
    assert (full["radii"] > 0).sum() > 40
