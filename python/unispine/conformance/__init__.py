"""A conformance kit for Gaussian-splatting rasterizers: any backend checked against this
reference, case by case, image and gradients, in one call.

    python -m unispine.conformance --backend gsplat-reference --dtype float64 --report out/

or, in Python / pytest::

    from unispine import conformance
    result = conformance.run("my_module:my_rasterization", dtype="float32", report="out")
    assert result, result.markdown()

The backend contract and the adapter from pre-activation parameters: ``backends`` (module
docs). The cases: ``cases`` (``case_names()``). The conventions a backend may declare, and the
presets of known implementations: ``CONVENTIONS``, ``PRESETS``. A failing case is explained by
the smallest set of convention switches under which the reference agrees with the backend.
The contract, the tolerances and the GPU command: ``docs/conformance.md`` in the repository.
"""

from .backends import BUILTIN, Backend, load
from .cases import all_cases, case_names, select
from .conventions import CONVENTIONS, DEFAULT, PRESETS, resolve
from .runner import TOLERANCES, CaseResult, Result, reference, run

__all__ = ["run", "Result", "CaseResult", "Backend", "load", "BUILTIN", "CONVENTIONS",
           "DEFAULT", "PRESETS", "TOLERANCES", "resolve", "all_cases", "case_names", "select",
           "reference"]
