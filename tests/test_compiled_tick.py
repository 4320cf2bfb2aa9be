"""The compiled tick against the same Python functions run by the interpreter (NUMBA_DISABLE_JIT=1).

Both runs tick the controller on the same random states (every input present, pushes that reach
the limits); every output must agree to 1e-9 (relative to its scale).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lapwrench.jit import jit_enabled

pytestmark = pytest.mark.slow  # compiled and uncompiled ticks in subprocesses

SCRIPT = Path(__file__).with_name("compiled_ticks.py")


def _run(out: Path, disable_jit: bool, extra: bool) -> dict[str, np.ndarray]:
    env = dict(os.environ, NUMBA_DISABLE_JIT="1" if disable_jit else "0")
    cmd = [sys.executable, str(SCRIPT), str(out), *(["--extra"] if extra else [])]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    with np.load(out) as z:
        return {k: z[k] for k in z.files}


@pytest.mark.parametrize("extra", [False, True], ids=["one-call", "with-extra-source"])
def test_compiled_tick_equals_the_interpreted_one(tmp_path: Path, extra: bool) -> None:
    compiled = _run(tmp_path / "jit.npz", disable_jit=False, extra=extra)
    interpreted = _run(tmp_path / "py.npz", disable_jit=True, extra=extra)
    assert compiled.pop("jit")[0] and not interpreted.pop("jit")[0]  # really one of each
    assert compiled.keys() == interpreted.keys()
    assert compiled["q_ref"].shape[0] >= 900
    for key, a in compiled.items():
        b = interpreted[key]
        scale = max(1.0, float(np.abs(b).max()))
        np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-9 * scale, err_msg=key)
    if extra:
        assert np.abs(compiled["W_pull"]).max() > 1.0  # the extra source acted


def test_the_jit_is_on_in_the_test_process() -> None:
    assert jit_enabled()
