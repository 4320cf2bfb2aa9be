"""Compilation of the 1 kHz maths with numba.

Every equation of the tick is one Python function decorated with :func:`kernel`: numba compiles it
in nopython mode (the machine code is cached next to the source, ``__pycache__``), and the
compiled tick (:mod:`lapwrench.tick_core`) calls the same functions, so there is one copy of the
maths. Under ``NUMBA_DISABLE_JIT=1`` the same functions run as plain Python (the tests compare
both to 1e-9).

Compilation happens in :func:`lapwrench.tick_core.warm_up`, which the controller calls when it
is built, before any robot moves; the first build on a fresh clone takes tens of seconds, later
ones load the cache.

**The cache is keyed by the source of every kernel module.** numba invalidates a cached function
only when *its own* file changes, not when a function it calls (in another file) does: after an
edit or an upgrade that changes ``motion/qp.py`` alone, ``tick_core``'s cached tick would still run
the old solver. So the cache lives in a directory named by a hash of every module of this package
that defines kernels (:func:`cache_dir`): any change to any of them starts a fresh cache. Constants
a kernel reads are frozen into its machine code, so they live in kernel modules too.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numba

F = TypeVar("F", bound=Callable[..., Any])

_PACKAGE = Path(__file__).resolve().parent
_KEEP_CACHES = 4  # older cache directories (other source versions) are pruned beyond this many


def source_hash(package: Path | None = None) -> str:
    """SHA-256 (16 hex digits) of every module of ``package`` (default: lapwrench's folder) that
    defines or configures kernels."""
    root = _PACKAGE if package is None else package
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        text = path.read_bytes()
        if b"@kernel" in text or b"njit" in text or path.name == "jit.py":
            h.update(str(path.relative_to(root)).encode() + b"\0" + text + b"\0")
    return h.hexdigest()[:16]


def cache_dir() -> Path:
    """Where the compiled kernels are cached: ``$NUMBA_CACHE_DIR`` (default ``~/.cache/lapwrench/numba``,
    or the temp folder when that is not writable) / :func:`source_hash`."""
    roots = [Path(os.environ["NUMBA_CACHE_DIR"])] if os.environ.get("NUMBA_CACHE_DIR") else []
    xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    roots += [Path(xdg) / "lapwrench" / "numba", Path(tempfile.gettempdir()) / f"lapwrench-numba-{os.getuid()}"]
    key = source_hash()
    for root in roots:
        try:
            (root / key).mkdir(parents=True, exist_ok=True)
        except OSError:
            continue
        if os.access(root / key, os.W_OK):
            _prune(root, key)
            return root / key
    raise RuntimeError(f"no writable folder for the compiled kernels among {[str(r) for r in roots]}")


def _prune(root: Path, keep: str) -> None:
    """Remove cache folders of other source versions beyond the newest few (older than a day)."""
    try:
        others = sorted((d for d in root.iterdir() if d.is_dir() and d.name != keep),
                        key=lambda d: d.stat().st_mtime, reverse=True)
    except OSError:
        return
    for d in others[_KEEP_CACHES:]:
        try:
            if time.time() - d.stat().st_mtime > 86400:
                shutil.rmtree(d, ignore_errors=True)
        except OSError:
            pass


# numba.config sets its options from the environment at run time (globals().update): mypy sees none of them
numba.config.CACHE_DIR = str(cache_dir())  # type: ignore[attr-defined]
# numba's hints that '@' is faster on contiguous arrays are for developers (bench/tick.py measures the
# tick); a user compiling on first use must not see them between the command's own lines
warnings.filterwarnings("ignore", category=numba.core.errors.NumbaPerformanceWarning)


def kernel(fn: F) -> F:
    """Compile ``fn`` in nopython mode with the on-disk cache; releases the GIL while it runs."""
    # a Dispatcher[F], called as F takes (under NUMBA_DISABLE_JIT, fn itself): no annotation says "an F"
    return numba.njit(cache=True, nogil=True)(fn)  # type: ignore[return-value]


def kernel_inlined(fn: F) -> F:
    """:func:`kernel`, inlined into its callers by numba (``inline='always'``): for the stages of the tick, each
    called once, whose calls hand on whole named tuples (a reference count on every array of them)."""
    return numba.njit(cache=True, nogil=True, inline="always")(fn)  # type: ignore[return-value]  # as kernel


def cache_is_warm() -> bool:
    """True when this source version's kernels have been compiled and cached before (a first run compiles
    them, minutes on a small machine: commands say so rather than look stalled)."""
    return not jit_enabled() or any(Path(numba.config.CACHE_DIR).rglob("*.nbi"))  # type: ignore[attr-defined]


def jit_enabled() -> bool:
    """False under ``NUMBA_DISABLE_JIT=1`` (the functions then run as plain Python)."""
    return not numba.config.DISABLE_JIT  # type: ignore[attr-defined]  # set at run time, as CACHE_DIR


def bind(fn: F, *example_args: Any) -> F:
    """The compiled ``fn`` for the argument types of ``example_args``, called without numba's dispatch.

    A numba dispatcher types every argument on every call; for the tick's named tuples that costs
    tens of µs. The entry point of one compiled signature skips it. So every later call must pass
    arguments of exactly these types (float64 C-contiguous arrays of the same dimensions, the same
    scalar kinds): the controller normalises its inputs before the call. Compiles (or loads the
    cache) now, so nothing compiles in the loop. Without the JIT, returns ``fn`` itself.
    """
    if not jit_enabled():
        return fn
    sig = tuple(numba.typeof(a) for a in example_args)
    return fn.compile(sig)  # type: ignore[attr-defined]  # a kernel (a Dispatcher) when the JIT is on
