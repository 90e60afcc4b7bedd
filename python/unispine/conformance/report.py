"""The report: a markdown table, the same in JSON, and a reproducer per failing case."""

import json
from pathlib import Path

import numpy as np

from .cases import GROUPS

SCRIPT = '''"""Reproduce conformance case {name!r}: python reproduce.py MODULE:FUNCTION
(the backend as given to `python -m unispine.conformance --backend`)."""
import importlib, sys
import numpy as np
z = np.load("case.npz")
mod, _, fn = sys.argv[1].partition(":")
backend = getattr(importlib.import_module(mod), fn)
names = ["means", "quats", "scales", "opacities", "colors"]  # gsplat's rasterization()
args = [z[n] for n in names] + [z["viewmats"], z["Ks"], int(z["width"]), int(z["height"])]
kw = {{"camera_model": str(z["camera_model"]), "backgrounds": z["backgrounds"]}}
if int(z["sh_degree"]) >= 0:
    kw["sh_degree"] = int(z["sh_degree"])
if "--numpy" not in sys.argv:
    import torch
    args = [torch.tensor(a) if isinstance(a, np.ndarray) else a for a in args]
    kw["backgrounds"] = torch.tensor(kw["backgrounds"])
out = backend(*args, **kw)
img = np.asarray((out[0] if isinstance(out, (tuple, list)) else out).tolist()).reshape(z["ref_image"].shape)
err = np.abs(img - z["ref_image"])
print("max |image - reference| =", err.max(), "at", np.unravel_index(err.argmax(), err.shape))
print("relative L2 =", np.linalg.norm(img - z["ref_image"]) / np.linalg.norm(z["ref_image"]))
'''


def _fmt(x):
    return "-" if x is None else f"{x:.1e}"


def markdown(result):
    d = result.to_dict()
    tol = d["tolerance"]
    lines = [
        f"# Conformance: {d['backend']}, {d['dtype']}",
        "",
        f"Declared conventions: `{d['declared_preset']}` "
        + (", ".join(f"{k} = {v[0]!r}" for k, v in d["differences_from_declared"].items())
           or "(the reference's own)")
        + f". Tolerance: relative L2 <= {tol['rel_l2']:g} and max error / max |ref| <= "
        f"{tol['max']:g} for the image and every gradient group.",
        "",
        "| case | status | image rel-L2 | image max | worst gradient group | its rel-L2 | its max"
        " | explained by |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for c in d["cases"]:
        g = c.get("groups", {})
        im = g.get("image", {})
        grads = {k: v for k, v in g.items() if k != "image"}
        if grads:
            wn = max(grads, key=lambda k: max(grads[k]["rel_l2"] / tol["rel_l2"],
                                              grads[k]["max"] / tol["max"]))
            wg = grads[wn]
        else:
            wn, wg = "-", {}
        exp = c.get("explained_by")
        exp = "-" if exp is None else (", ".join(f"{n} = {v!r}" for n, v in exp) or "-")
        if c["status"] in ("error", "bad-output", "timeout"):
            exp = c["message"].replace("|", "/")[:120]
        if c.get("tolerance") not in (None, tol):
            exp += f" (case tolerance {c['tolerance']['rel_l2']:g} / {c['tolerance']['max']:g})"
        lines.append(f"| {c['name']} | {c['status']} | {_fmt(im.get('rel_l2'))} | "
                     f"{_fmt(im.get('max'))} | {wn} | {_fmt(wg.get('rel_l2'))} | "
                     f"{_fmt(wg.get('max'))} | {exp} |")
    n_pass = sum(c["status"] == "pass" for c in d["cases"])
    lines += ["", f"{n_pass} of {len(d['cases'])} cases pass."]
    if d["explained_differences"]:
        lines.append("Convention differences found: " + ", ".join(
            f"{k} = {v!r}" for k, v in d["explained_differences"].items()) + ".")
    return "\n".join(lines) + "\n"


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items() if not k.startswith("_")}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    return x


def write(result, folder):
    """summary.md, report.json and, per failing case, ``cases/<name>/{case.npz,
    reproduce.py}``."""
    from .backends import activate, sh_degree
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.md").write_text(result.markdown())
    (out / "report.json").write_text(json.dumps(_jsonable(result.to_dict()), indent=1))
    dt = np.dtype(result.dtype)
    for c in result.cases:
        if c.passed or "_case" not in c:
            continue
        case = c["_case"]
        d = out / "cases" / c["name"]
        d.mkdir(parents=True, exist_ok=True)
        args, _ = activate(case, dt)
        arrays = dict(args)
        arrays.update({"pre_" + g: case["params"][g] for g in GROUPS})
        arrays.update(viewmats=case["viewmats"].astype(dt), Ks=case["Ks"].astype(dt),
                      width=case["width"], height=case["height"],
                      camera_model=case["camera_model"], color_mode=case["color_mode"],
                      active_features=case["active_features"],
                      backgrounds=np.full((1, 1), case["background"], dtype=dt),
                      sh_degree=(sh_degree(case["active_features"])
                                 if case["color_mode"] == "sh" else -1),
                      d_image=case["d_image"],
                      conventions=json.dumps(result.backend.conventions))
        if "_outputs" in c:
            image, grads, ref = c["_outputs"]
            arrays["ref_image"] = ref["image"]
            arrays["backend_image"] = image
            for g in GROUPS:
                arrays["ref_d_" + g] = ref[g]
                if grads is not None:
                    arrays["backend_d_" + g] = grads[g]
        else:
            from .runner import reference
            arrays["ref_image"] = reference(case, result.backend.conventions)["image"]
        np.savez(d / "case.npz", **arrays)
        (d / "reproduce.py").write_text(SCRIPT.format(name=c["name"]))
        c["reproducer"] = str(d)
    (out / "report.json").write_text(json.dumps(_jsonable(result.to_dict()), indent=1))
