"""The conformance kit (`unispine.conformance`) against real backends: gsplat 1.5.3's PyTorch
reference (PyPI, run on the CPU with the kit's stand-ins for its two CUDA-only helpers), our own
torch bridge, deliberately broken copies of gsplat's reference (each break must be found and
named), and backends that break the contract (raise, wrong shape / dtype, NaN, hang).

torch and gsplat are needed: without them these tests skip with a message, except under CI
(CI=true), where a missing dependency fails them (`.ci/run` installs both).
"""

import importlib
import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from unispine import conformance

ON_CI = os.environ.get("CI") == "true"


def need(module, how):
    try:
        return importlib.import_module(module)
    except ImportError as e:
        msg = f"{module} is not installed ({e}): {how}"
        if ON_CI:
            pytest.fail("CI=true but " + msg)
        print("\nSKIPPING LOUDLY: " + msg, file=sys.stderr)
        pytest.skip(msg)


@pytest.fixture(scope="module")
def torch():
    return need("torch", "pip install torch")


@pytest.fixture(scope="module")
def gsplat(torch):
    return need("gsplat.cuda._torch_impl", "BUILD_NO_CUDA=1 pip install gsplat==1.5.3")


@pytest.fixture(scope="module")
def gsplat_cpu(gsplat):
    """The kit's CPU runner of gsplat's reference (it imports torch, so only after the check)."""
    return importlib.import_module("unispine.conformance.gsplat_cpu")


def show(res):
    print("\n" + res.markdown())


# The differences between gsplat 1.5.3 and 3DGS that change an output. Two of the declared
# ones cannot: the stop test (T (1 - alpha) <= 1e-4 against < 1e-4) differs only at an exact
# tie, which no case builds; and with 3.33 sigma the per-axis and eigenvalue radii differ only
# on pixels beyond 3.33 sigma along a row or column, where alpha < o / 255 is skipped anyway.
GSPLAT_VS_3DGS = {"alpha_max": 0.999, "radius_sigmas": 3.33, "near_plane": 0.01,
                  "jacobian_limits": "principal-point", "clamp_gradient": "zero"}


def test_gsplat_reference_passes_every_case_in_float64(gsplat, tmp_path):
    t0 = time.perf_counter()
    res = conformance.run("gsplat-reference", "float64", report=tmp_path)
    show(res)
    assert res.passed, res.markdown()
    assert len(res.cases) == 18
    for c in res.cases:
        assert c["gradients"], c["name"]
        assert set(c["groups"]) == {"image", "means", "quats", "log_scales",
                                    "opacity_logits", "features"}
        for g, v in c["groups"].items():
            assert v["rel_l2"] <= 1e-10 and v["max"] <= 1e-10, (c["name"], g, v)
        if "reference_vs_golden" in c:
            assert c["reference_vs_golden"] <= 1.0, c["name"]
    rep = json.loads((tmp_path / "report.json").read_text())
    assert rep["passed"] and len(rep["cases"]) == len(res.cases)
    assert (tmp_path / "summary.md").read_text().count("| pass |") == len(res.cases)
    print(f"float64 run: {time.perf_counter() - t0:.1f} s")


def test_gsplat_reference_passes_every_case_in_float32(gsplat):
    res = conformance.run("gsplat-reference", "float32")
    show(res)
    assert res.passed, res.markdown()


def test_under_3dgs_conventions_the_report_lists_exactly_the_differences(gsplat, tmp_path):
    res = conformance.run("gsplat-reference", "float64", conventions="3dgs", report=tmp_path)
    show(res)
    assert not res.passed
    assert res.exit_code == 1
    failing = [c for c in res.cases if not c.passed]
    for c in failing:
        assert c["status"] == "fail", c
        assert c["explained_by"], (c["name"], c["message"])
    assert res.differences == GSPLAT_VS_3DGS
    # The near-plane case differs by the near plane alone; the alpha-clamp case needs the clamp.
    assert res.case("near-plane")["explained_by"] == [["near_plane", 0.01]]
    assert ["alpha_max", 0.999] in res.case("alpha-clamp")["explained_by"]
    # A reproducer per failing case that runs and shows the image difference.
    d = tmp_path / "cases" / "alpha-clamp"
    z = np.load(d / "case.npz")
    assert z["ref_image"].shape == (48, 64)
    out = subprocess.run([sys.executable, "reproduce.py",
                          "unispine.conformance.gsplat_cpu:rasterization"], cwd=d,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "max |image - reference|" in out.stdout
    assert len((d / "reproduce.py").read_text().splitlines()) <= 25


def test_our_torch_bridge_passes_bit_for_bit_in_float64(torch):
    res = conformance.run("torch-bridge", "float64")
    show(res)
    assert res.passed, res.markdown()
    for c in res.cases:
        for g, v in c["groups"].items():
            assert v["max"] == 0.0, (c["name"], g, v)


# ---- deliberately broken copies of gsplat's reference (wrapped at test time) ----------------

BREAK_CASES = ["random-medium", "beyond-3-sigma", "alpha-clamp", "saturating", "tile-straddle",
               "sh-degree-3"]


def test_break_dropped_transmittance_gradient_is_found_and_named(gsplat_cpu, monkeypatch, torch):
    """The transmittance of the scan detached: the image is right, gradients are not."""
    orig = gsplat_cpu._render_weight_from_alpha

    def broken(alphas, ray_indices=None, n_rays=None, **kw):
        w, t = orig(alphas, ray_indices=ray_indices, n_rays=n_rays)
        return t.detach() * alphas, t.detach()
    monkeypatch.setattr(gsplat_cpu, "_render_weight_from_alpha", broken)
    res = conformance.run("gsplat-reference", "float64", cases=BREAK_CASES)
    show(res)
    assert not res.passed
    for c in res.cases:
        assert c["status"] == "fail", c["name"]
        assert c["groups"]["image"]["pass"], c["name"]
        assert not c["groups"]["opacity_logits"]["pass"], c["name"]
        assert c["explained_by"] is None
        assert "no combination of known conventions explains it" in c["message"]
        assert c["diagnosis"] == "gradient", c["name"]


def test_break_wrong_pixel_centre_is_found_and_named(gsplat_cpu, monkeypatch):
    """Pixels sampled at integer coordinates (the mean shifted by half a pixel in the pair
    kernel and in gsplat's `accumulate`; the tiles unchanged)."""
    from gsplat.cuda import _torch_impl as ti
    pairs, acc = gsplat_cpu._indices_in_range, ti.accumulate

    def pairs_broken(a, b, t, means2d, *rest):
        return pairs(a, b, t, means2d + 0.5, *rest)

    def acc_broken(means2d, *rest):
        return acc(means2d + 0.5, *rest)
    monkeypatch.setattr(gsplat_cpu, "_indices_in_range", pairs_broken)
    monkeypatch.setattr(ti, "accumulate", acc_broken)
    res = conformance.run("gsplat-reference", "float64", cases=BREAK_CASES)
    show(res)
    assert not res.passed
    assert res.differences == {"pixel_center": 0.0}
    for c in res.cases:
        assert c["explained_by"] == [["pixel_center", 0.0]], c["name"]


def test_break_three_sigma_cut_is_found_and_named(gsplat, monkeypatch, torch):
    """Tile rectangles from 3 instead of 3.33 standard deviations."""
    from gsplat.cuda import _torch_impl as ti
    proj = ti._fully_fused_projection

    def broken(means, covars, viewmats, Ks, width, height, **kw):
        radii, means2d, depths, conics, comp = proj(means, covars, viewmats, Ks, width, height,
                                                   **kw)
        a, b, c = conics.detach().unbind(-1)
        det = a * c - b * b
        sx, sy = torch.sqrt(c / det), torch.sqrt(a / det)
        r = torch.stack([torch.ceil(3.0 * sx), torch.ceil(3.0 * sy)], -1)
        m = means2d.detach()
        inside = (m[..., 0] + r[..., 0] > 0) & (m[..., 0] - r[..., 0] < width) \
            & (m[..., 1] + r[..., 1] > 0) & (m[..., 1] - r[..., 1] < height)
        keep = (radii > 0).all(-1) & inside
        return (r * keep[..., None]).int(), means2d, depths, conics, comp
    monkeypatch.setattr(ti, "_fully_fused_projection", broken)
    res = conformance.run("gsplat-reference", "float64", cases=BREAK_CASES)
    show(res)
    assert not res.passed
    assert res.differences == {"radius_sigmas": 3.0}
    assert res.case("beyond-3-sigma")["explained_by"] == [["radius_sigmas", 3.0]]


# ---- backends that break the contract ----------------------------------------------------

def test_bad_backends_are_reported_per_case_and_the_rest_still_run(gsplat_cpu, torch):
    good = gsplat_cpu.rasterization
    state = {"n": 0}

    def flaky(means, *a, **kw):
        state["n"] += 1
        k = state["n"]
        if k == 1:
            raise RuntimeError("kernel launch failed")
        img = good(means, *a, **kw)[0]
        if k == 2:
            return img[..., 0]                       # wrong shape
        if k == 3:
            return img.float()                       # wrong dtype
        if k == 4:
            return img * float("nan")                # NaN
        if k == 5:
            time.sleep(30)                           # hangs
        return img
    flaky.conformance_conventions = "gsplat-1.5.3"
    names = ["random-sparse", "random-medium", "tile-straddle", "alpha-clamp", "saturating",
             "beyond-3-sigma"]
    res = conformance.run(flaky, "float64", cases=names, timeout=3.0)
    show(res)
    st = {c["name"]: (c["status"], c["message"]) for c in res.cases}
    assert st["random-sparse"][0] == "error" and "kernel launch failed" in st["random-sparse"][1]
    assert st["random-medium"][0] == "bad-output" and "shape" in st["random-medium"][1]
    assert st["tile-straddle"][0] == "bad-output" and "dtype" in st["tile-straddle"][1]
    assert st["alpha-clamp"][0] == "bad-output" and "non-finite" in st["alpha-clamp"][1]
    assert st["saturating"][0] == "timeout"
    assert st["beyond-3-sigma"][0] == "pass"
    assert res.exit_code == 1


def test_command_line_exit_codes_and_report(tmp_path, torch):
    cmd = [sys.executable, "-m", "unispine.conformance", "--backend", "torch-bridge",
           "--cases", "random-sparse", "alpha-clamp", "--report", str(tmp_path)]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "| random-sparse | pass |" in out.stdout
    assert json.loads((tmp_path / "report.json").read_text())["passed"]
    bad = subprocess.run(cmd[:3] + ["--backend", "torch-bridge", "--conventions",
                                    "gsplat-1.5.3", "--cases", "alpha-clamp"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 1, bad.stdout + bad.stderr
    assert "alpha_max" in bad.stdout
    usage = subprocess.run(cmd[:3] + ["--backend", "no-such-thing"], capture_output=True,
                           text=True, timeout=60)
    assert usage.returncode == 2 and "built-in name" in usage.stderr


def test_unknown_case_and_convention_are_errors():
    with pytest.raises(ValueError, match="unknown cases"):
        conformance.run("torch-bridge", cases=["nope"])
    with pytest.raises(ValueError, match="unknown conventions"):
        conformance.resolve({"alpha": 0.9})
    import unispine
    from conftest import look_at_camera, params, scene
    vm, k, w, h = look_at_camera()
    with pytest.raises(ValueError, match="conventions.alpha_max"):
        unispine.rasterize(*params(scene(3, 1)), vm, k, w, h, conventions={"alpha_max": 1.5})
    with pytest.raises(ValueError, match="unknown field"):
        unispine.rasterize(*params(scene(3, 1)), vm, k, w, h, conventions={"alpha": 0.9})


def test_a_numpy_backend_with_a_vjp_is_checked_through_the_adapter(gsplat_cpu, torch):
    """The numpy contract: arrays in, an image array out, gradients from a `vjp` callable (here
    gsplat's reference behind numpy, its vjp by autograd); the kit chains them to the
    pre-activation groups."""
    names = ["means", "quats", "scales", "opacities", "colors", "viewmats", "Ks"]

    def call(arrays, w, h, kw):
        ts = [torch.tensor(a, requires_grad=i < 5) for i, a in enumerate(arrays)]
        kwt = dict(kw, backgrounds=torch.tensor(kw["backgrounds"]))
        return ts, gsplat_cpu.rasterization(*ts, w, h, **kwt)[0]

    def fn(*a, **kw):
        return call(a[:7], a[7], a[8], kw)[1].detach().numpy()

    def vjp(d_image, *a, **kw):
        ts, img = call(a[:7], a[7], a[8], kw)
        (img * torch.tensor(d_image)).sum().backward()
        return {n: t.grad.numpy() for n, t in zip(names[:5], ts)}
    b = conformance.Backend(fn, "gsplat via numpy", "gsplat-1.5.3", array="numpy", vjp=vjp)
    res = conformance.run(b, "float64", cases=["random-sparse", "sh-degree-1", "rirf-xgaussian"])
    show(res)
    assert res.passed, res.markdown()
    assert all(c["gradients"] for c in res.cases)
    no_vjp = conformance.run(conformance.Backend(fn, "forward only", "gsplat-1.5.3",
                                                 array="numpy"), cases=["random-sparse"])
    assert no_vjp.passed and set(no_vjp.cases[0]["groups"]) == {"image"}
