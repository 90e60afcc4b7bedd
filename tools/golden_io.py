"""Reading golden files (format: golden/README.md) and checking a reference against them.

Shared by the independent numpy references in this folder; it holds no equation, only the
file format and the comparison rule |ours - golden| <= abs + rel |golden| of each file.
"""
import json
import pathlib

import numpy as np

GOLDEN = pathlib.Path(__file__).resolve().parent.parent / "golden"


def arr(v):
    """A golden array {"shape": [...], "data": [...]} as a numpy array."""
    return np.array(v["data"], dtype=np.float64).reshape(v["shape"])


def golden_value(v):
    """A golden output: an array object or a plain number / list."""
    if isinstance(v, dict):
        return arr(v)
    return np.asarray(v, dtype=np.float64)


def check_folders(folders, run_case):
    """Recompute every golden file of `folders` with run_case(folder, stem, inputs) -> {key:
    array} and compare within the file's tolerance. Prints one line per output; returns the
    process exit code (1 if any output, file or folder fails)."""
    failures = 0
    n_cases = 0
    for folder in folders:
        files = sorted((GOLDEN / folder).glob("*.json"))
        if not files:
            print(f"FAIL {folder}: no golden files")
            failures += 1
        for path in files:
            case = json.loads(path.read_text())
            tol_abs, tol_rel = case["tolerance"]["abs"], case["tolerance"]["rel"]
            ref = run_case(folder, path.stem, case["inputs"])
            if set(ref) != set(case["outputs"]):
                print(f"FAIL {path.name}: outputs {sorted(case['outputs'])} vs {sorted(ref)}")
                failures += 1
                continue
            n_cases += 1
            for key, mine in ref.items():
                gold = golden_value(case["outputs"][key])
                mine = np.asarray(mine, dtype=np.float64)
                if gold.shape != mine.shape:
                    print(f"FAIL {folder}/{path.name} {key}: shape {gold.shape} vs {mine.shape}")
                    failures += 1
                    continue
                err = np.abs(mine - gold)
                bad = err > tol_abs + tol_rel * np.abs(gold)
                scale = max(np.abs(gold).max(), 1e-300)
                status = "FAIL" if bad.any() else "ok  "
                print(f"{status} {folder}/{path.name} {key}: max |diff| {err.max():.3e} "
                      f"(max-abs-normalised {err.max() / scale:.3e})")
                if bad.any():
                    failures += 1
    print(f"{n_cases} cases, {failures} failures")
    return 1 if failures else 0
