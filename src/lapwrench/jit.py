"""Compilation of the 1 kHz maths with numba.

Every equation of the tick is one Python function decorated with :func:`kernel`: numba compiles it
in nopython mode (the machine code is cached next to the source, ``__pycache__``), and the
compiled tick (:mod:`lapwrench.tick_core`) calls the same functions, so there is one copy of the
maths. Under ``NUMBA_DISABLE_JIT=1`` the same functions run as plain Python (the tests compare
both to 1e-9).

Compilation happens in :func:`lapwrench.tick_core.warm_up`, which the controller calls when it
is built, before any robot moves; the first build on a fresh clone takes tens of seconds, later
ones load the cache.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numba

F = TypeVar("F", bound=Callable[..., Any])


def kernel(fn: F) -> F:
    """Compile ``fn`` in nopython mode with the on-disk cache; releases the GIL while it runs."""
    return numba.njit(cache=True, nogil=True)(fn)  # type: ignore[no-any-return]


def jit_enabled() -> bool:
    """False under ``NUMBA_DISABLE_JIT=1`` (the functions then run as plain Python)."""
    return not numba.config.DISABLE_JIT


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
    return fn.compile(sig)  # type: ignore[attr-defined, no-any-return]
