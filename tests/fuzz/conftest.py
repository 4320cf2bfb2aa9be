"""Property-based fuzzing of every input edge (issue 11), with a fixed seed.

``derandomize=True`` makes each run draw the same examples, so CI is reproducible; no deadline,
because a busy CI machine must not fail a property on wall-clock time. The example budget is
``LAPWRENCH_FUZZ_EXAMPLES`` (default 200 per property), sized so the suite stays about a minute.
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

settings.register_profile(
    "lapwrench-ci",
    derandomize=True,
    deadline=None,
    max_examples=int(os.environ.get("LAPWRENCH_FUZZ_EXAMPLES", "200")),
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    database=None,
    print_blob=True,
)
settings.load_profile("lapwrench-ci")
