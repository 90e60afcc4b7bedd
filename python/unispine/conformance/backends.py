"""Backends: what the kit calls, and the adapter from the kit's pre-activation parameters.

The contract (gsplat's ``rasterization`` arguments, one camera, one channel)::

    backend(means, quats, scales, opacities, colors, viewmats, Ks, width, height, *,
            camera_model, backgrounds, sh_degree=None)  ->  image [C, H, W, 1]
                                                          (or a tuple whose first item it is)

- ``means`` [N, 3] world units; ``quats`` [N, 4] (w, x, y, z), unnormalised; ``scales`` [N, 3]
  standard deviations (after exp); ``opacities`` [N] (after the sigmoid);
- ``colors``: the intensity [N, 1] (the kit evaluates the RIRF models of Eq. (2) itself), or,
  with ``sh_degree`` d, the SH coefficients [N, (d + 1)^2, 1] (colour = max(0, 0.5 + SH . c),
  3DGS's basis, direction from the camera centre to the mean);
- ``viewmats`` [C, 4, 4] world-to-camera (OpenCV axes), ``Ks`` [C, 3, 3], ``camera_model``
  'pinhole' or 'ortho', ``backgrounds`` [C, 1]; C = 1 in every case;
- every array in the dtype of the run (float64 or float32), torch tensors (``array="torch"``)
  or numpy arrays (``array="numpy"``).

Gradients: a torch backend is differentiated by autograd; a numpy backend may give ``vjp``,
called with ``d_image`` [C, H, W, 1] and the same arguments, returning a dict of gradients
named like the arguments (``means``, ``quats``, ``scales``, ``opacities``, ``colors``). The kit
chains them to the pre-activation groups it compares: d log_scales = d scales * scales,
d opacity_logits = d opacities * o (1 - o), d features from d colors through Eq. (2) (or the
SH coefficients directly).

A backend that takes the pre-activation parameters instead (``params="preactivated"``, like
``unispine.torch_bridge.rasterize``) is called as
``backend(means, quats, log_scales, opacity_logits, features, viewmats, Ks, width, height, *,
camera_model, color_mode, active_features, background) -> image [C, H, W]``.
"""

import importlib

import numpy as np

from .conventions import resolve

# Eq. (2)'s lambda_k: the real SH normalisation constants in 3DGS's order and signs.
LAMBDA = np.array([
    0.28209479177387814, -0.4886025119029199, 0.4886025119029199, -0.4886025119029199,
    1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
    0.5462742152960396, -0.5900435899266435, 2.890611442640554, -0.4570457994644658,
    0.3731763325901154, -0.4570457994644658, 1.445305721320277, -0.5900435899266435,
])


class Backend:
    """A rasterizer to check: ``fn`` (see the module docs for the call), the conventions it
    declares (a preset name of ``unispine.conformance.PRESETS`` or a dict), ``params``
    ('activated' or 'preactivated'), ``array`` ('torch' or 'numpy'), an optional ``vjp`` for
    numpy backends, and a ``name`` for the report."""

    def __init__(self, fn, name=None, conventions="unispine", params="activated",
                 array="torch", vjp=None):
        if params not in ("activated", "preactivated"):
            raise ValueError(f"params must be 'activated' or 'preactivated', got {params!r}")
        if array not in ("torch", "numpy"):
            raise ValueError(f"array must be 'torch' or 'numpy', got {array!r}")
        self.fn, self.params, self.array, self.vjp = fn, params, array, vjp
        self.name = name or getattr(fn, "__qualname__", repr(fn))
        self.conventions = resolve(conventions)
        self.declared = conventions if isinstance(conventions, str) else "custom"

    @property
    def differentiable(self):
        return self.array == "torch" or self.vjp is not None


def _torch_bridge():
    from ..torch_bridge import rasterize
    return Backend(rasterize, "torch-bridge", "unispine", params="preactivated")


def _gsplat_reference():
    from .gsplat_cpu import rasterization
    return Backend(rasterization, "gsplat-reference (gsplat 1.5.3 _torch_impl.py on CPU)",
                   "gsplat-1.5.3")


def _gsplat_cuda():
    import torch
    from gsplat import rasterization

    def on_gpu(means, quats, scales, opacities, colors, viewmats, Ks, width, height, **kw):
        dev = torch.device("cuda")
        args = [t.to(dev) for t in (means, quats, scales, opacities, colors, viewmats, Ks)]
        if kw.get("backgrounds") is not None:
            kw["backgrounds"] = kw["backgrounds"].to(dev)
        img = rasterization(*args, width, height, **kw)[0]
        return img.cpu()
    return Backend(on_gpu, "gsplat-cuda (gsplat.rasterization on the GPU)", "gsplat-1.5.3")


BUILTIN = {
    "torch-bridge": _torch_bridge,
    "gsplat-reference": _gsplat_reference,
    "gsplat-cuda": _gsplat_cuda,
}


def load(spec, conventions=None):
    """A ``Backend`` from a built-in name, a ``MODULE:FUNCTION`` string, a ``Backend`` or a
    callable (a plain callable is an activated torch backend; attributes ``conformance_*`` on it
    (``conformance_conventions``, ``conformance_params``, ``conformance_array``,
    ``conformance_vjp``) declare the rest). ``conventions`` overrides the declared ones."""
    if isinstance(spec, Backend):
        b = spec
    elif isinstance(spec, str) and spec in BUILTIN:
        b = BUILTIN[spec]()
    elif isinstance(spec, str):
        if ":" not in spec:
            raise ValueError(f"backend {spec!r}: give a built-in name {sorted(BUILTIN)} or "
                             "MODULE:FUNCTION")
        mod, _, attr = spec.partition(":")
        obj = importlib.import_module(mod)
        for part in attr.split("."):
            obj = getattr(obj, part)
        b = load(obj)
        if not isinstance(obj, Backend):
            b.name = spec
    elif callable(spec):
        b = Backend(spec, getattr(spec, "__qualname__", None),
                    getattr(spec, "conformance_conventions", "unispine"),
                    getattr(spec, "conformance_params", "activated"),
                    getattr(spec, "conformance_array", "torch"),
                    getattr(spec, "conformance_vjp", None))
    else:
        raise TypeError(f"not a backend: {spec!r}")
    if conventions is not None:
        b = Backend(b.fn, b.name, conventions, b.params, b.array, b.vjp)
    return b


def sh_degree(active):
    return {1: 0, 4: 1, 9: 2, 16: 3}[active]


def activate(case, dtype):
    """The backend's arguments (numpy, ``dtype``) of a case, and what the chain rule needs."""
    p = {k: v.astype(np.float64) for k, v in case["params"].items()}
    k = case["active_features"]
    mode = case["color_mode"]
    scales = np.exp(p["log_scales"])
    opac = 1.0 / (1.0 + np.exp(-p["opacity_logits"]))
    s = p["features"][:, :k] @ LAMBDA[:k]
    if mode == "rirf-paper":
        colors = (1.0 / (1.0 + np.exp(-s)))[:, None]
    elif mode == "rirf-xgaussian":
        colors = np.maximum(0.0, 0.5 + s)[:, None]
    elif mode == "sh":
        colors = p["features"][:, :k, None]
    else:
        raise ValueError(mode)
    args = {"means": p["means"], "quats": p["quats"], "scales": scales, "opacities": opac,
            "colors": colors}
    args = {n: a.astype(dtype) for n, a in args.items()}
    return args, {"scales": scales, "opac": opac, "s": s, "colors": colors}


def chain(case, aux, g):
    """Gradients of the activated arguments -> the pre-activation groups (float64)."""
    k = case["active_features"]
    mode = case["color_mode"]
    n = len(case["params"]["means"])
    out = {"means": g["means"], "quats": g["quats"],
           "log_scales": g["scales"] * aux["scales"],
           "opacity_logits": g["opacities"] * aux["opac"] * (1.0 - aux["opac"])}
    feat = np.zeros((n, 16))
    dc = g["colors"]
    if mode == "sh":
        feat[:, :k] = dc[:, :k, 0]
    elif mode == "rirf-paper":
        c = aux["colors"][:, 0]
        feat[:, :k] = (dc[:, 0] * c * (1.0 - c))[:, None] * LAMBDA[:k]
    else:
        feat[:, :k] = (dc[:, 0] * (0.5 + aux["s"] > 0))[:, None] * LAMBDA[:k]
    out["features"] = feat
    return out
