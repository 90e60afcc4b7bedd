"""The bindings give the very bits of the `unispine render` binary on the same scene."""

import json
import subprocess

import numpy as np
import pytest

import unispine
from conftest import GEOMETRY, params, scene, unispine_binary, write_ply

ANGLE_DEG = 37.0


@pytest.mark.parametrize("precision", ["f64", "f32"])
@pytest.mark.parametrize("color_mode", ["rirf-paper", "sh"])
def test_render_and_gradients_match_the_binary_bit_for_bit(tmp_path, precision, color_mode):
    exe = unispine_binary()
    sc = scene(300, seed=11)
    write_ply(tmp_path / "m.ply", sc)
    (tmp_path / "g.json").write_text(json.dumps(GEOMETRY))
    h, w = GEOMETRY["nDetector"]
    weights = np.random.default_rng(5).normal(size=(h, w))
    np.save(tmp_path / "w.npy", weights)
    subprocess.run(
        [exe, "render", "--ply", tmp_path / "m.ply", "--geometry", tmp_path / "g.json",
         "--angle-deg", str(ANGLE_DEG), "--color", color_mode, "--background", "0.25",
         "--grad-weights", tmp_path / "w.npy", "--precision", precision, "--out", tmp_path / "out"],
        check=True, capture_output=True,
    )
    bin_image = np.load(tmp_path / "out" / "image.npy")
    bin_grads = np.load(tmp_path / "out" / "grads.npz")

    dtype = np.float64 if precision == "f64" else np.float32
    kw = dict(geometry=GEOMETRY, angles=ANGLE_DEG * (np.pi / 180.0), color_mode=color_mode,
              background=0.25)
    image, trans, n_contrib = unispine.rasterize(*params(sc, dtype), **kw)
    assert image.dtype == dtype and image.shape == (1, h, w)
    # The binary writes the image as float32.
    assert np.array_equal(image[0].astype(np.float32), bin_image)
    assert np.count_nonzero(n_contrib) > 0.5 * h * w, "the scene covers most of the image"
    assert trans.min() < 0.5

    g = unispine.rasterize_vjp(*params(sc, dtype), d_image=weights[None].astype(dtype), **kw)
    assert np.array_equal(g["image"], image)
    f64 = lambda a: np.asarray(a, dtype=np.float64)  # noqa: E731
    assert np.array_equal(f64(g["d_means"]), bin_grads["xyz"])
    assert np.array_equal(f64(g["d_log_scales"]), bin_grads["scale"])
    assert np.array_equal(f64(g["d_quats"]), bin_grads["rot"])
    assert np.array_equal(f64(g["d_opacity_logits"]), bin_grads["opacity"])
    # Stored features: f_dc_0..2 then f_rest_{c * 15 + k - 1}; each is d_feature / 3.
    d_f = f64(g["d_features"]) * (1.0 / 3.0)
    want = np.concatenate([np.repeat(d_f[:, :1], 3, axis=1)] + [d_f[:, 1:]] * 3, axis=1)
    assert np.array_equal(want, bin_grads["features"])
    assert np.abs(g["d_means"]).max() > 0 and np.abs(g["d_features"]).max() > 0


def test_repeated_calls_and_threads_give_identical_bits():
    sc = scene(200, seed=3)
    kw = dict(geometry=GEOMETRY, angles=[0.1, 1.3])
    a = unispine.rasterize(*params(sc), **kw)[0]
    b = unispine.rasterize(*params(sc), **kw)[0]
    assert a.shape == (2, 48, 64) and np.array_equal(a, b)
    assert not np.array_equal(a[0], a[1])
