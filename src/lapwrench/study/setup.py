"""The ``study`` extra (Ray with Tune, pandas, pyarrow), installed on first use of ``sweep`` or ``tune``.

The requirements are read from the installed package's metadata (``Requires-Dist: ...; extra ==
"study"``), so pyproject.toml stays their one source. ``./run.sh test`` installs them with the dev
extra; a user who runs ``lapwrench sweep`` first gets them installed into the same environment, with a
message, or a one-line error saying what to install if pip cannot.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import re
import subprocess
import sys

MODULES = ("ray", "ray.tune", "pandas", "pyarrow")
FALLBACK = ("ray[tune]>=2.50,<3", "pyarrow>=15", "pandas>=2.2")  # if the package metadata is not installed


class SetupError(RuntimeError):
    """The study extra is missing and could not be installed."""


def requirements() -> tuple[str, ...]:
    """The ``study`` extra's requirement strings, from the installed metadata."""
    try:
        reqs = importlib.metadata.requires("lapwrench") or []
    except importlib.metadata.PackageNotFoundError:
        return FALLBACK
    pattern = re.compile(r"""^(.*?)\s*;\s*extra\s*==\s*["']study["']\s*$""")
    found = tuple(m.group(1) for r in reqs if (m := pattern.match(r)))
    return found or FALLBACK


def missing() -> list[str]:
    """The study modules that do not import here."""
    out = []
    for name in MODULES:
        try:
            importlib.import_module(name)
        except ImportError:
            out.append(name)
    return out


def ensure(command: str, install: bool = True) -> None:
    """Make sure the study extra imports; install it with pip on first use (message on stderr)."""
    if not missing():
        return
    reqs = requirements()
    hint = "pip install " + " ".join(f"'{r}'" for r in reqs)
    if not install:
        raise SetupError(f"needs {', '.join(missing())}: {hint}")
    print(f"[lapwrench] {command}: installing the study extra on first use ({', '.join(reqs)}) ...", file=sys.stderr)
    try:
        proc = subprocess.run([sys.executable, "-m", "pip", "install", "-q", *reqs], capture_output=True, text=True)
    except OSError as exc:
        raise SetupError(f"cannot run pip ({exc.strerror or exc}); install the study extra yourself: {hint}") from exc
    importlib.invalidate_caches()
    if proc.returncode != 0 or missing():
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1][:200]
        raise SetupError(f"installing the study extra failed ({last}); install it yourself: {hint}")
