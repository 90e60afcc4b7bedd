"""Rasterizer conventions as data: the named settings of the reference renderer
(``unispine.rasterize(..., conventions=...)``, Rust ``render::Conventions``) and the presets of
known implementations.

Each convention has the reference's default, the other values known implementations use, and
where each value comes from (the upstream repository and file the fact was read from).
"""

# name -> (default, alternatives tried when explaining a failure, what it means)
CONVENTIONS = {
    "alpha_max": (0.99, (0.999,),
                  "alpha = min(alpha_max, o G): 0.99 in 3DGS (graphdeco-inria/diff-gaussian-"
                  "rasterization cuda_rasterizer/forward.cu), 0.999 in gsplat v1.5.3 "
                  "(gsplat/cuda/csrc/RasterizeToPixels3DGSFwd.cu)"),
    "t_stop": ("exclusive", ("inclusive",),
               "a pixel stops, without blending the splat, when T (1 - alpha) < 1e-4 "
               "('exclusive', 3DGS) or <= 1e-4 ('inclusive', gsplat v1.5.3); observable only "
               "when T (1 - alpha) equals 1e-4 exactly"),
    "radius_sigmas": (3.0, (3.33,),
                      "the tile rectangle's half-size in standard deviations: 3 (3DGS), 3.33 "
                      "(gsplat v1.5, gsplat/cuda/_torch_impl.py _fully_fused_projection)"),
    "radius_rule": ("eigen", ("axes",),
                    "'eigen': one radius from the largest eigenvalue of Sigma2D with a 0.1 "
                    "floor on the discriminant (3DGS); 'axes': one per axis from the Sigma2D "
                    "diagonal (gsplat v1.5)"),
    "eps2d": (0.3, (0.1,),
              "dilation Sigma2D + eps2d I: 0.3 (3DGS, gsplat), 0.1 (brush mip-splatting mode)"),
    "pixel_center": (0.5, (0.0,),
                     "pixel (c, r) is sampled at (c + pixel_center, r + pixel_center) given K: "
                     "0.5 (gsplat, brush, this reference), 0 (3DGS's CUDA, whose implicit "
                     "principal point is (W - 1)/2)"),
    "clamp_gradient": ("zero", ("pass",),
                       "gradient through a clamped alpha: 'zero' (the exact derivative; gsplat, "
                       "brush) or 'pass' (as if unclamped; 3DGS's cuda_rasterizer/backward.cu)"),
    "near_plane": (0.2, (0.01,),
                   "Gaussians with camera depth z <= near_plane are culled: 0.2 (3DGS "
                   "auxiliary.h in_frustum), 0.01 (gsplat rasterization() default)"),
    "jacobian_limits": ("symmetric", ("principal-point",),
                        "limits of x/z inside the EWA Jacobian: +-1.3 tan(fov/2) (3DGS) or "
                        "-(cx/fx + 0.3 tan) .. (W - cx)/fx + 0.3 tan (gsplat _persp_proj); equal "
                        "when cx = W/2"),
}

DEFAULT = {k: v[0] for k, v in CONVENTIONS.items()}

PRESETS = {
    # This reference's own rules (3DGS's values with gsplat's pixel centres and tile rule).
    "unispine": dict(DEFAULT),
    # graphdeco-inria/diff-gaussian-rasterization (2023): the same forward as the default; its
    # backward passes the gradient through a clamped alpha.
    "3dgs": dict(DEFAULT, clamp_gradient="pass"),
    # nerfstudio-project/gsplat v1.5.3, gsplat/cuda/_torch_impl.py and csrc/ (classic mode).
    "gsplat-1.5.3": dict(DEFAULT, alpha_max=0.999, t_stop="inclusive", radius_sigmas=3.33,
                         radius_rule="axes", near_plane=0.01,
                         jacobian_limits="principal-point"),
}


def resolve(conv):
    """A full conventions dict from a preset name, a partial dict (the rest default) or None."""
    if conv is None:
        return dict(DEFAULT)
    if isinstance(conv, str):
        if conv not in PRESETS:
            raise ValueError(f"unknown conventions preset {conv!r}; presets: {sorted(PRESETS)}")
        return dict(PRESETS[conv])
    unknown = set(conv) - set(CONVENTIONS)
    if unknown:
        raise ValueError(f"unknown conventions {sorted(unknown)}; known: {sorted(CONVENTIONS)}")
    return dict(DEFAULT, **conv)


def switches(declared):
    """Every single-convention change of ``declared``: (name, value) pairs, value != declared."""
    out = []
    for name, (default, alts, _) in CONVENTIONS.items():
        for v in (default,) + tuple(alts):
            if v != declared[name]:
                out.append((name, v))
    return out


def differences(a, b):
    """{name: (a value, b value)} where two full conventions dicts differ."""
    return {k: (a[k], b[k]) for k in CONVENTIONS if a[k] != b[k]}
