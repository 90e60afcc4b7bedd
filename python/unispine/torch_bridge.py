"""A ``torch.autograd.Function`` around ``unispine.rasterize`` / ``rasterize_vjp``.

Needs torch at import time only (the package builds and works without it). The forward and
backward passes run on the CPU in the dtype of ``means`` (use float64 for gradient checks);
tensors on another device are copied to the CPU and the results copied back.

    from unispine.torch_bridge import rasterize
    image = rasterize(means, quats, log_scales, opacity_logits, features,
                      viewmats, Ks, width, height)          # [C, H, W]
    image.backward(d_image)                                 # exact VJP of the forward
    torch.autograd.gradcheck(lambda *p: rasterize(*p, viewmats, Ks, width, height),
                             (means, quats, log_scales, opacity_logits, features))
"""

import torch
from torch.autograd.function import once_differentiable

from . import _native

_GROUPS = ("means", "quats", "log_scales", "opacity_logits", "features")


def _np(t):
    return t.detach().cpu().numpy()


class Rasterize(torch.autograd.Function):
    """``Rasterize.apply(means, quats, log_scales, opacity_logits, features, camera, settings)``.

    ``camera``: dict of the camera keywords of ``unispine.rasterize`` (numpy arrays or
    tensors without gradient); ``settings``: dict of ``color_mode``, ``active_features``,
    ``background``. Returns the image [C, H, W]. The backward pass is
    ``unispine.rasterize_vjp`` (first order only).
    """

    @staticmethod
    def forward(ctx, means, quats, log_scales, opacity_logits, features, camera, settings):
        params = (means, quats, log_scales, opacity_logits, features)
        image, _, _ = _native.rasterize(*(_np(p) for p in params), **camera, **settings)
        ctx.save_for_backward(*params)
        ctx.camera, ctx.settings = camera, settings
        return torch.from_numpy(image).to(means.device)

    @staticmethod
    @once_differentiable
    def backward(ctx, d_image):
        params = ctx.saved_tensors
        means = params[0]
        d = d_image.detach().to(device="cpu", dtype=means.dtype).contiguous().numpy()
        g = _native.rasterize_vjp(*(_np(p) for p in params), d_image=d, **ctx.camera,
                                  **ctx.settings)
        grads = tuple(torch.from_numpy(g["d_" + k]).to(means.device) for k in _GROUPS)
        return grads + (None, None)


def rasterize(means, quats, log_scales, opacity_logits, features, viewmats=None, Ks=None,
              width=None, height=None, *, camera_model="pinhole", geometry=None, angles=None,
              color_mode="rirf-paper", active_features=16, background=0.0):
    """``unispine.rasterize`` on tensors, differentiable in the five parameter groups.

    Arguments and conventions as ``unispine.rasterize``; returns the image [C, H, W] only.
    """
    camera = {"camera_model": camera_model}
    if geometry is not None:
        camera.update(geometry=geometry, angles=angles)
    else:
        camera.update(viewmats=_np(torch.as_tensor(viewmats)), Ks=_np(torch.as_tensor(Ks)),
                      width=int(width), height=int(height))
    settings = {"color_mode": color_mode, "active_features": int(active_features),
                "background": float(background)}
    return Rasterize.apply(means, quats, log_scales, opacity_logits, features, camera, settings)
