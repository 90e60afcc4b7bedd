#!/usr/bin/env python3
"""Write tiny NAF-layout dataset pickles for tests/dataset_pickle.rs.

The layout is the one written by NAF / SAX-NeRF `dataGenerator/generateData.py` and read by
X-Gaussian / UniSpine-GS `scene/dataset_readers.py`: a plain dict with the TIGRE geometry keys
(mm), `image` ([x, y, z] float32), `train` / `val` = {`angles` (float64 radians),
`projections` (float32 [N, v, u])}. The training projections are a negative-stride view
(`[:, ::-1, :]`, exactly as the generators store TIGRE's output), the validation ones are
contiguous, so both of numpy's array reductions occur (`_reconstruct` + BUILD, and in
protocol 5 `_frombuffer` + BYTEARRAY8).

Run it once with numpy 1.x and once with numpy 2.x: the module path numpy writes into the
stream (`numpy.core` vs `numpy._core`) depends on the installed major version, and each run
writes the files of its own version:

    python3 tools/make_pickle_fixtures.py            # -> tests/fixtures/naf_p{2,4,5}_np{1|2}.pickle

It also writes `naf_expected.json` (every value of the dict as plain JSON, the same for every
fixture) and, with numpy 2.x, a protocol-5 file with a Fortran-order image
(`naf_p5_fortran_np2.pickle`), one that references an array twice (`naf_shared_np2.pickle`),
and the bad fixtures (`bad_*.pickle`) whose errors the tests check.
"""
import json
import os
import pickle
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "tests", "fixtures")

NV, NU = 3, 4  # detector rows (v), columns (u): unequal, so a transpose shows
NX, NY, NZ = 2, 3, 4


def naf_dict(fortran_image=False):
    k = np.arange(3, dtype=np.float64)
    train_angles = np.linspace(0, np.pi, 3 + 1)[:-1]
    val_angles = train_angles + np.pi / 6
    # Distinct float32 values: view * 100 + row * 10 + col, scaled.
    base = (k[:, None, None] * 100 + np.arange(NV)[None, :, None] * 10
            + np.arange(NU)[None, None, :]).astype(np.float32) * np.float32(1e-3)
    train = (base + np.float32(0.25))[:, ::-1, :]  # negative stride, like [:, ::-1, :]
    val = np.ascontiguousarray(base + np.float32(0.5))
    image = (np.arange(NX * NY * NZ, dtype=np.float32).reshape(NX, NY, NZ) / np.float32(23.0))
    if fortran_image:
        image = np.asfortranarray(image)
    return {
        "numTrain": 3,
        "numVal": 3,
        "DSD": 1500.0,
        "DSO": np.float64(1000.0),  # a numpy scalar, as converters sometimes store
        "nDetector": [NV, NU],
        "dDetector": [1.5, 2.0],
        "nVoxel": [NX, NY, NZ],
        "dVoxel": np.array([1.0, 0.5, 2.0]),
        "offOrigin": [0.0, 0.0, 1.0],
        "offDetector": [0.5, -0.25],
        "accuracy": 0.5,
        "mode": "cone",
        "filter": None,
        "totalAngle": 180.0,
        "startAngle": 0.0,
        "randomAngle": False,
        "convert": True,
        "rescale_slope": 1.0,
        "rescale_intercept": 0.0,
        "normalize": True,
        "noise": 0,
        "image": image,
        "train": {"angles": train_angles, "projections": train},
        "val": {"angles": val_angles, "projections": val},
    }


def to_json(v):
    if isinstance(v, dict):
        return {k: to_json(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [to_json(x) for x in v]
    if isinstance(v, np.ndarray):
        return {"shape": list(v.shape), "values": [float(x) for x in v.ravel(order="C")]}
    if isinstance(v, np.generic):
        return v.item()
    return v


def dump(name, obj, protocol):
    path = os.path.join(OUT, name)
    with open(path, "wb") as f:
        pickle.dump(obj, f, protocol=protocol)
    print(f"{name}: {os.path.getsize(path)} bytes")


def main():
    os.makedirs(OUT, exist_ok=True)
    major = int(np.__version__.split(".")[0])
    print(f"numpy {np.__version__}")
    for p in (2, 4, 5):
        # Fortran-order image in the protocol-4 files (BUILD with is_fortran = True).
        dump(f"naf_p{p}_np{major}.pickle", naf_dict(fortran_image=(p == 4)), p)
    with open(os.path.join(OUT, "naf_expected.json"), "w") as f:
        json.dump(to_json(naf_dict()), f, indent=1)
    if major >= 2:
        # Variants that are valid: no `image`, and an `image` coarser than nVoxel.
        d = naf_dict()
        del d["image"]
        dump("naf_noimage.pickle", d, 5)
        d = naf_dict()
        d["image"] = np.ascontiguousarray(d["image"][:1, :, ::2])
        dump("naf_small_image.pickle", d, 4)
        # Protocol 5 with a Fortran-order image: numpy 2 writes
        # `_frombuffer(buf, dtype, shape, 'F')`, whose buffer is in Fortran order.
        dump("naf_p5_fortran_np2.pickle", naf_dict(fortran_image=True), 5)
        # One array referenced twice (pickle's memo): valid, and must be accepted.
        d = naf_dict()
        d["image_again"] = d["image"]
        dump("naf_shared_np2.pickle", d, 4)
        d = naf_dict()
        del d["DSO"]
        dump("bad_missing_dso.pickle", d, 4)
        d = naf_dict()
        d["train"]["projections"] = d["train"]["projections"][:, :, :3]
        dump("bad_shape.pickle", d, 4)
        d = naf_dict()
        d["val"]["projections"][1, 2, 3] = np.nan
        dump("bad_nan.pickle", d, 5)
        d = naf_dict()
        d["val"] = {"angles": np.zeros(0), "projections": np.zeros((0, NV, NU), np.float32)}
        d["numVal"] = 0
        dump("bad_zero_views.pickle", d, 4)
        d = naf_dict()
        import fractions
        d["accuracy"] = fractions.Fraction(1, 2)
        dump("bad_global.pickle", d, 4)
        d = naf_dict()
        d["image"] = d["image"].astype(np.complex64)
        dump("bad_dtype.pickle", d, 4)


if __name__ == "__main__":
    sys.exit(main())
