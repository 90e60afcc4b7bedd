"""Gradients of the bindings against an independent PyTorch rasterizer (autograd), in float64,
and `torch.autograd.gradcheck` through the torch bridge."""

import numpy as np
import pytest

import unispine
from conftest import look_at_camera, params, scene

torch = pytest.importorskip("torch", reason="torch is not installed: pip install torch")
from torch_reference import render as torch_render  # noqa: E402
from unispine.torch_bridge import rasterize as rasterize_torch  # noqa: E402

GROUPS = ("means", "quats", "log_scales", "opacity_logits", "features")


def max_norm_err(a, b):
    """max |a - b| / max |b| (max-abs-normalised error)."""
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / max(np.abs(b).max(), 1e-300))


@pytest.mark.parametrize("color_mode", ["rirf-paper", "sh"])
def test_gradients_match_an_independent_torch_rasterizer(color_mode):
    sc = scene(60, seed=21, extent=9.0, log_scale=(-0.7, 0.6), logit=(-2.5, 5.0))
    vm, k, w, h = look_at_camera()
    ps = params(sc)
    d_image = np.random.default_rng(2).normal(size=(1, h, w))
    ours = unispine.rasterize_vjp(*ps, vm, k, w, h, d_image=d_image, color_mode=color_mode,
                                  background=0.1)

    ts = [torch.tensor(p, requires_grad=True) for p in ps]
    img = torch_render(*ts, torch.tensor(vm[0]), torch.tensor(k[0]), w, h,
                       color_mode=color_mode, background=0.1)
    (img * torch.tensor(d_image[0])).sum().backward()

    assert max_norm_err(ours["image"][0], img.detach().numpy()) < 1e-12
    drawn = (ours["radii"][0] > 0).sum()
    assert drawn > 30, "most Gaussians are drawn"
    for name, t in zip(GROUPS, ts):
        err = max_norm_err(ours["d_" + name], t.grad.numpy())
        print(f"{color_mode} d_{name}: max-abs-normalised error {err:.2e}")
        assert err < 1e-10, name
        assert np.abs(t.grad.numpy()).max() > 0


def test_gradcheck_through_the_torch_bridge():
    sc = scene(6, seed=4, extent=6.0, log_scale=(0.0, 0.8), logit=(-1.0, 1.5))
    vm, k, w, h = look_at_camera(width=20, height=18, f=90.0)
    ts = tuple(torch.tensor(p, requires_grad=True) for p in params(sc))
    fn = lambda *p: rasterize_torch(*p, vm, k, w, h)  # noqa: E731
    assert torch.autograd.gradcheck(fn, ts, eps=1e-6, atol=1e-7, rtol=1e-6)


def test_torch_bridge_backward_is_rasterize_vjp():
    sc = scene(30, seed=8, extent=9.0)
    vm, k, w, h = look_at_camera()
    ps = params(sc)
    ts = [torch.tensor(p, requires_grad=True) for p in ps]
    img = rasterize_torch(*ts, vm, k, w, h)
    g = torch.randn(img.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    img.backward(g)
    ours = unispine.rasterize_vjp(*ps, vm, k, w, h, d_image=g.numpy())
    for name, t in zip(GROUPS, ts):
        assert np.array_equal(t.grad.numpy(), ours["d_" + name]), name
