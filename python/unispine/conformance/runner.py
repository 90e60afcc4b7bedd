"""Running the cases against a backend, comparing with the reference, explaining failures."""

import threading
import time
import traceback

import numpy as np

from .. import _native
from . import backends as bk
from .cases import GROUPS, select
from .conventions import CONVENTIONS, DEFAULT, differences, switches

# Pass when, for the image and every gradient group, both the relative L2 error
# ||yours - ref|| / ||ref|| and the max-normalised error max|yours - ref| / max|ref| are at most
# these (the reference is always the float64 render of the same float32-exact inputs).
# float64: the bound; measured round-off between implementations is ~1e-14.
# float32: from the float32 runs of the torch bridge and gsplat's reference over every case
# (docs/conformance.md, "Tolerances"; worst rel-L2 2.8e-5, worst max 6.7e-5), with a margin for
# a backend's different summation order; two cases have their own (cases.FLOAT32_TOLERANCE).
TOLERANCES = {
    "float64": {"rel_l2": 1e-10, "max": 1e-10},
    "float32": {"rel_l2": 1e-4, "max": 1e-3},
}

REPORT_GROUPS = ("image",) + GROUPS


class BadOutput(Exception):
    """The backend returned something that breaks the contract (shape, dtype, NaN)."""


class Timeout(Exception):
    pass


def _call(fn, timeout):
    """fn() in a daemon thread; Timeout when it has not returned after ``timeout`` s (the
    thread is abandoned, the run goes on)."""
    box = {}

    def target():
        try:
            box["out"] = fn()
        except BaseException as e:  # noqa: BLE001 - reported per case
            box["exc"] = e
            box["tb"] = traceback.format_exc(limit=-3)
    th = threading.Thread(target=target, daemon=True)
    th.start()
    th.join(timeout)
    if th.is_alive():
        raise Timeout(f"no result after {timeout:g} s")
    if "exc" in box:
        e = box["exc"]
        e.tb_text = box["tb"]
        raise e
    return box["out"]


def _as_numpy(x, what):
    try:
        import torch
        if isinstance(x, torch.Tensor):
            return x.detach().cpu().numpy()
    except ImportError:
        pass
    if isinstance(x, np.ndarray):
        return x
    raise BadOutput(f"{what} is a {type(x).__name__}, not an array or tensor")


def _check(arr, shape, dtype, what):
    if tuple(arr.shape) != tuple(shape):
        raise BadOutput(f"{what} has shape {list(arr.shape)}, expected {list(shape)}")
    if arr.dtype != dtype:
        raise BadOutput(f"{what} has dtype {arr.dtype}, expected {np.dtype(dtype).name}")
    bad = ~np.isfinite(arr)
    if bad.any():
        raise BadOutput(f"{what} holds {int(bad.sum())} non-finite values (first at "
                        f"{[int(i) for i in np.argwhere(bad)[0]]})")


def run_backend(backend, case, dtype):
    """The backend's image [H, W] and pre-activation gradients (float64 numpy; None when the
    backend gives none) for ``case`` in ``dtype``."""
    dt = np.dtype(dtype)
    h, w = case["height"], case["width"]
    vm, ks = case["viewmats"].astype(dt), case["Ks"].astype(dt)
    if backend.params == "activated":
        args, aux = bk.activate(case, dt)
        kw = {"camera_model": case["camera_model"],
              "backgrounds": np.full((1, 1), case["background"], dtype=dt)}
        if case["color_mode"] == "sh":
            kw["sh_degree"] = bk.sh_degree(case["active_features"])
        names = ["means", "quats", "scales", "opacities", "colors"]
        shape = (1, h, w, 1)
    else:
        args = {g: case["params"][g].astype(dt) for g in GROUPS}
        kw = {"camera_model": case["camera_model"], "color_mode": case["color_mode"],
              "active_features": case["active_features"], "background": case["background"]}
        names, aux, shape = list(GROUPS), None, (1, h, w)
    d_image = case["d_image"].reshape(shape)
    grads = None
    if backend.array == "torch":
        import torch
        tens = {n: torch.tensor(args[n], requires_grad=True) for n in names}
        kwt = {k: (torch.tensor(v) if isinstance(v, np.ndarray) else v) for k, v in kw.items()}
        out = backend.fn(*[tens[n] for n in names], torch.tensor(vm), torch.tensor(ks), w, h,
                         **kwt)
        img_t = out[0] if isinstance(out, (tuple, list)) else out
        img = _as_numpy(img_t, "the image")
        _check(img, shape, dt, "the image")
        if img_t.requires_grad:
            (img_t * torch.tensor(d_image.astype(dt))).sum().backward()
            grads = {}
            for n in names:
                g = tens[n].grad
                grads[n] = np.zeros(args[n].shape) if g is None else g.numpy()
    else:
        out = backend.fn(*[args[n] for n in names], vm, ks, w, h, **kw)
        img = _as_numpy(out[0] if isinstance(out, (tuple, list)) else out, "the image")
        _check(img, shape, dt, "the image")
        if backend.vjp is not None:
            g = backend.vjp(d_image.astype(dt), *[args[n] for n in names], vm, ks, w, h, **kw)
            grads = {n: _as_numpy(g[n], f"the gradient of {n}") for n in names}
    if grads is not None:
        for n in names:
            _check(grads[n], args[n].shape, dt, f"the gradient of `{n}`")
        grads = {n: v.astype(np.float64) for n, v in grads.items()}
        if aux is not None:
            grads = bk.chain(case, aux, grads)
    return img.reshape(h, w).astype(np.float64), grads


def reference(case, conventions):
    """The reference (float64) image [H, W] and gradients of ``case`` under ``conventions``."""
    p = case["params"]
    r = _native.rasterize_vjp(
        *[p[g] for g in GROUPS], case["viewmats"], case["Ks"], case["width"], case["height"],
        d_image=case["d_image"], camera_model=case["camera_model"],
        color_mode=case["color_mode"], active_features=case["active_features"],
        background=case["background"], conventions=conventions)
    out = {"image": r["image"][0]}
    out.update({g: r["d_" + g] for g in GROUPS})
    return out


def errors(mine, ref):
    """(relative L2, max-normalised) error of ``mine`` against ``ref``."""
    d = np.asarray(mine, dtype=np.float64) - ref
    nd, nr = float(np.linalg.norm(d)), float(np.linalg.norm(ref))
    md, mr = float(np.abs(d).max(initial=0.0)), float(np.abs(ref).max(initial=0.0))
    rel = nd / nr if nr > 0 else (0.0 if nd == 0 else float("inf"))
    mx = md / mr if mr > 0 else (0.0 if md == 0 else float("inf"))
    return rel, mx


def compare(image, grads, ref, tol):
    """Per group: rel_l2, max, pass; and the worst ratio error / tolerance."""
    groups, worst = {}, 0.0
    for g in REPORT_GROUPS:
        if g != "image" and grads is None:
            continue
        rel, mx = errors(image if g == "image" else grads[g], ref[g])
        ok = rel <= tol["rel_l2"] and mx <= tol["max"]
        groups[g] = {"rel_l2": rel, "max": mx, "pass": ok}
        worst = max(worst, rel / tol["rel_l2"], mx / tol["max"])
    return groups, worst


def explain(case, image, grads, declared, tol):
    """The smallest set of convention switches (searched greedily) under which the reference
    agrees with the backend: at each step the single switch, or failing that the pair of
    switches, that lowers the worst error / tolerance most is taken, until the case passes;
    then switches that are not needed are dropped. Returns (switches as [[name, value], ...]
    or None, the best worst-ratio, reference renders made)."""
    cache = {}

    def score(conv):
        key = tuple(sorted(conv.items()))
        if key not in cache:
            cache[key] = compare(image, grads, reference(case, conv), tol)[1]
        return cache[key]

    current = dict(declared)
    best = score(current)
    chosen = []
    while best > 1.0:
        free = [(n, v) for n, v in switches(current) if n not in dict(chosen)]
        step = None
        for size in (1, 2):
            opts = []
            for i, a in enumerate(free):
                if size == 1:
                    opts.append(((a,), score(dict(current, **{a[0]: a[1]}))))
                    continue
                for b in free[i + 1:]:
                    if b[0] != a[0]:
                        opts.append(((a, b), score(dict(current, **{a[0]: a[1], b[0]: b[1]}))))
            if opts:
                sw, sc = min(opts, key=lambda o: o[1])
                if sc < best:
                    step = (sw, sc)
                    break
        if step is None:
            break
        for n, v in step[0]:
            current[n] = v
            chosen.append((n, v))
        best = step[1]
    if best > 1.0:
        return None, best, len(cache)
    for n, v in list(chosen):
        trial = dict(current, **{n: declared[n]})
        s = score(trial)
        if s <= 1.0:
            current, best = trial, s
            chosen.remove((n, v))
    return [[n, v] for n, v in chosen], best, len(cache)


class CaseResult(dict):
    """One case's outcome (a dict, JSON-ready): ``name``, ``stresses``, ``status`` ('pass',
    'fail', 'error', 'bad-output', 'timeout'), ``message``, ``groups`` {group: {rel_l2, max,
    pass}}, ``explained_by``, ``seconds``."""

    @property
    def passed(self):
        return self["status"] == "pass"


class Result:
    """The outcome of a run: ``cases`` (``CaseResult``), ``passed``, ``exit_code``,
    ``differences`` (the convention switches that explain the failures), ``markdown()``,
    ``to_dict()``; ``assert result, result.markdown()`` works in pytest."""

    def __init__(self, backend, dtype, cases, tol):
        self.backend, self.dtype, self.cases, self.tolerance = backend, dtype, cases, tol

    @property
    def passed(self):
        return all(c.passed for c in self.cases)

    def __bool__(self):
        return self.passed

    @property
    def exit_code(self):
        return 0 if self.passed else 1

    def case(self, name):
        return next(c for c in self.cases if c["name"] == name)

    @property
    def differences(self):
        """{convention: value} switched in the explanation of any failing case."""
        out = {}
        for c in self.cases:
            for n, v in c.get("explained_by") or []:
                out[n] = v
        return out

    def to_dict(self):
        return {"backend": self.backend.name, "dtype": self.dtype,
                "declared_conventions": self.backend.conventions,
                "declared_preset": self.backend.declared,
                "differences_from_declared": differences(self.backend.conventions, DEFAULT),
                "tolerance": self.tolerance, "passed": self.passed,
                "explained_differences": self.differences,
                "cases": [dict(c) for c in self.cases]}

    def markdown(self):
        from .report import markdown
        return markdown(self)


def run_case(backend, case, dtype, tol, timeout, do_explain=True):
    tol = case.get("tolerance_" + dtype, tol)
    golden_case = case
    # The backend and the reference read the same numbers: the inputs rounded to the run's
    # dtype (a no-op for float64, and for the float32-exact generated cases).
    case = dict(case, params={g: v.astype(dtype).astype(np.float64)
                              for g, v in case["params"].items()},
                d_image=case["d_image"].astype(dtype).astype(np.float64))
    res = CaseResult(name=case["name"], stresses=case["stresses"], status="pass", message="",
                     groups={}, explained_by=None, seconds={}, tolerance=tol)
    t0 = time.perf_counter()
    ref = reference(case, backend.conventions)
    t1 = time.perf_counter()
    res["seconds"]["reference"] = t1 - t0
    if "golden" in case:
        ref0 = reference(golden_case, DEFAULT)
        gt, worst = case["golden"], 0.0
        for g in REPORT_GROUPS:
            want = gt["outputs"]["image" if g == "image" else "d_" + g]
            want = want.reshape(ref0[g].shape)
            lim = gt["tolerance"]["abs"] + gt["tolerance"]["rel"] * np.abs(want)
            worst = max(worst, float((np.abs(ref0[g] - want) / lim).max()))
        res["reference_vs_golden"] = worst
    try:
        t2 = time.perf_counter()
        image, grads = _call(lambda: run_backend(backend, case, dtype), timeout)
        res["seconds"]["backend"] = time.perf_counter() - t2
    except Timeout as e:
        res.update(status="timeout", message=str(e))
        return res
    except BadOutput as e:
        res.update(status="bad-output", message=str(e))
        return res
    except Exception as e:  # noqa: BLE001 - a raising backend is a per-case outcome
        tb = getattr(e, "tb_text", "")
        res.update(status="error", message=f"{type(e).__name__}: {e}", traceback=tb)
        return res
    t3 = time.perf_counter()
    groups, worst = compare(image, grads, ref, tol)
    res["seconds"]["compare"] = time.perf_counter() - t3
    res["groups"] = groups
    res["gradients"] = grads is not None
    res["worst_ratio"] = worst
    if worst <= 1.0:
        return res
    res["status"] = "fail"
    bad = [g for g, v in groups.items() if not v["pass"]]
    # "gradient": the image agrees and only gradients differ (a backward bug or a gradient
    # convention); "image": the forward differs.
    res["diagnosis"] = "gradient" if groups["image"]["pass"] else "image"
    res["message"] = ("exceeds the tolerance in " + ", ".join(bad)
                      + (" (the image agrees: a backward-pass difference)"
                         if res["diagnosis"] == "gradient" else ""))
    if do_explain:
        t4 = time.perf_counter()
        sw, best, tried = explain(case, image, grads, backend.conventions, tol)
        res["seconds"]["explain"] = time.perf_counter() - t4
        res["explained_by"] = sw
        res["explain_renders"] = tried
        if sw is None:
            res["message"] += (f"; no combination of known conventions explains it (best "
                               f"error / tolerance {best:.3g})")
        else:
            res["message"] += "; differs from the reference only by " + ", ".join(
                f"{n} = {v!r}" for n, v in sw)
    res["_outputs"] = (image, grads, ref)
    return res


def run(backend, dtype="float64", cases="all", report=None, timeout=120.0, conventions=None,
        explain=True):
    """Run the conformance cases against ``backend`` (a built-in name, ``MODULE:FUNCTION``,
    a ``Backend`` or a callable) in ``dtype``; ``cases`` 'all' or a list of names; write the
    report (markdown, JSON, reproducers) to the folder ``report`` if given. ``conventions``
    overrides the backend's declared ones (a preset name or a dict). Returns a ``Result``."""
    if dtype not in TOLERANCES:
        raise ValueError(f"dtype must be 'float64' or 'float32', got {dtype!r}")
    names = None if cases in (None, "all") else ([cases] if isinstance(cases, str) else cases)
    # The case names first: a wrong name is reported without loading the backend.
    chosen = list(select(names))
    b = bk.load(backend, conventions)
    tol = TOLERANCES[dtype]
    results = []
    for case in chosen:
        r = run_case(b, case, dtype, tol, timeout, explain)
        r["_case"] = case
        results.append(r)
    res = Result(b, dtype, results, tol)
    if report is not None:
        from .report import write
        write(res, report)
    for r in results:
        r.pop("_outputs", None)
        r.pop("_case", None)
    return res
