"""The golden values stored in graded test modules are what diffusers (the reference) returns now,
and are written exactly as ``python tests/exercises/golden.py`` writes them."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

_spec = importlib.util.spec_from_file_location("exercise_golden", Path(__file__).resolve().parent / "exercises" / "golden.py")
golden = importlib.util.module_from_spec(_spec)  # tests/exercises/golden.py (tests/ is not a package)
_spec.loader.exec_module(golden)


@pytest.mark.parametrize("name", golden.MODULES)
def test_stored_golden_values_are_what_diffusers_returns(name):
    pytest.importorskip("diffusers")
    module = golden.load(name)
    fresh = module.golden_values()
    assert fresh.keys() == module.GOLDEN.keys()
    for run, fields in fresh.items():
        assert fields.keys() == module.GOLDEN[run].keys(), run
        for field, values in fields.items():
            np.testing.assert_allclose(module.GOLDEN[run][field], values, rtol=1e-6, atol=1e-7,
                                       err_msg=f"{name} {run} {field}: regenerate with python tests/exercises/golden.py")
    text = (golden.HERE / name).read_text()
    block = text[text.index(golden.BEGIN): text.index(golden.END) + len(golden.END)]
    assert block == golden.render(module.GOLDEN), f"{name}: the golden block is not as golden.py writes it"
