"""unispine: the CPU reference of UniSpine-GS (X-ray / ultrasound Gaussian splatting) from Python.

A deterministic, f64-capable oracle for checking GPU rasterizers and their gradients:

- ``rasterize`` / ``rasterize_vjp``: the tile rasterizer (Eqs. 1-5) and its exact
  vector-Jacobian product (every parameter group, and the screen-space splat gradients);
- ``project`` / ``project_vjp``: the projection stage alone (means2d, conics, radii, depths)
  and its backward;
- ``drr``: Siddon and trilinear DRRs of a volume;
- ``ssim``, ``loss``: SSIM and the hybrid loss of Eq. (8) with their gradients;
- ``golden_cases``: the repository's golden files as dicts of numpy arrays.

Names follow gsplat's where they exist (means, quats, viewmats, Ks, width, height); the
parametrisation is said in the name where it differs (``log_scales``, ``opacity_logits``).
float64 in, float64 out; float32 in, float32 out. ``unispine.torch_bridge`` wraps the
rasterizer as a ``torch.autograd.Function`` when torch is installed (torch is not needed
otherwise).
"""

import json as _json

import numpy as _np

from ._native import drr, loss, project, project_vjp, rasterize, rasterize_vjp, ssim
from . import _native

__all__ = [
    "rasterize",
    "rasterize_vjp",
    "project",
    "project_vjp",
    "drr",
    "ssim",
    "loss",
    "golden_cases",
    "golden_folders",
]


def _decode(x):
    """JSON values of a golden file: ``{"shape", "data"}`` objects become float64 arrays."""
    if isinstance(x, dict):
        if set(x) == {"shape", "data"}:
            return _np.array(x["data"], dtype=_np.float64).reshape(x["shape"])
        return {k: _decode(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_decode(v) for v in x]
    return x


def golden_folders():
    """Names of the golden folders (``eq01-covariance``, ...), sorted."""
    return sorted({folder for folder, _, _ in _native.golden_files()})


def golden_cases(folder=None):
    """The golden cases compiled into the package (the repository's ``golden/`` folder).

    ``folder``: a folder name such as ``"eq03-projection"`` or ``"eq03-projection-vjp"`` (the
    backward cases of a stage), an equation such as ``"eq03"`` (every folder of that equation),
    or ``None`` for every case.

    Returns a list of dicts, one per case, sorted by folder then case name, with keys
    ``folder``, ``name``, ``equation``, ``description``, ``inputs``, ``outputs``,
    ``tolerance`` (``{"abs", "rel"}``: pass when ``|yours - golden| <= abs + rel |golden|``)
    and ``checked_by``. Arrays (``{"shape", "data"}`` in the files) are float64 numpy arrays,
    row-major; images are [rows, cols] with row 0 at the top; quaternions are (w, x, y, z);
    see ``golden/README.md`` for each folder's fields.
    """
    out = []
    for fold, name, text in _native.golden_files():
        if folder is not None and fold != folder and not (
                len(folder) == 4 and folder.startswith("eq") and fold.startswith(folder + "-")):
            continue
        case = _decode(_json.loads(text))
        case["folder"] = fold
        case["name"] = name
        out.append(case)
    if folder is not None and not out:
        raise ValueError(f"no golden folder matches {folder!r}; folders: {golden_folders()}")
    return out
