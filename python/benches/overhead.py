"""Python call overhead of `unispine.rasterize` over the library call it wraps.

Scene: 50,000 Gaussians in a 200 mm cube, cone beam (DSD 1500 mm, DSO 1000 mm), 256 x 256
detector of 1.5 mm pixels, float32 (the training precision) and float64. For each precision,
the same scene is rendered `--repeats` times, alternately, through `unispine.rasterize` (argument reading and
checking, output arrays) and through the Rust `render::forward` alone, timed inside Rust; the
script prints both medians and the overhead. Run from the repository root after
`pip install ./python`:

    python3 python/benches/overhead.py [--repeats 15]
"""

import argparse
import statistics
import time

import numpy as np

import unispine
from unispine import _native

GEOMETRY = {
    "DSD": 1500.0, "DSO": 1000.0, "nDetector": [256, 256], "dDetector": [1.5, 1.5],
    "nVoxel": [100, 100, 100], "dVoxel": [2.0, 2.0, 2.0], "mode": "cone",
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--gaussians", type=int, default=50_000)
    a = ap.parse_args()
    rng = np.random.default_rng(0)
    n = a.gaussians
    scene = [rng.uniform(-100, 100, (n, 3)), rng.normal(size=(n, 4)),
             rng.uniform(np.log(0.5), np.log(3.0), (n, 3)), rng.uniform(-3, 1, n),
             rng.normal(scale=0.5, size=(n, 16))]
    print(f"{n} Gaussians, 256 x 256, cone beam; median of {a.repeats} calls each")
    for dtype in (np.float32, np.float64):
        ps = [p.astype(dtype) for p in scene]
        kw = dict(geometry=GEOMETRY, angles=0.7)
        unispine.rasterize(*ps, **kw)  # warm-up
        # Interleaved, so that a change of machine load affects both series alike.
        py_times, rust_times = [], []
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            unispine.rasterize(*ps, **kw)
            py_times.append(time.perf_counter() - t0)
            rust_times += _native._bench_render_forward(*ps, repeats=1, **kw)
        py_med, rust_med = statistics.median(py_times), statistics.median(rust_times)
        print(f"{np.dtype(dtype).name}: python unispine.rasterize {py_med * 1e3:8.2f} ms   "
              f"rust render::forward {rust_med * 1e3:8.2f} ms   "
              f"overhead {100 * (py_med / rust_med - 1):+.1f} %")


if __name__ == "__main__":
    main()
