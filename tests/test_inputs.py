"""lapwrench.inputs: registered inputs and the checks every reading goes through."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from lapwrench.inputs import InputSpec, Reading, as_f64_c, fresh_stamp, is_f64_c, real_array

SPEC = InputSpec("pedal", (2,), 0.0, 1.0, max_age=0.05)


def test_a_valid_reading_passes_as_it_is() -> None:
    r = Reading(np.array([0.0, 1.0]), 1.0)
    assert SPEC.check(r, 1.01) == (r, "")


def test_a_reading_of_lists_and_ints_is_converted() -> None:
    valid, _ = SPEC.check(Reading([0, 1], 1.0), 1.0)  # type: ignore[arg-type]
    assert valid is not None and valid.value.dtype == np.float64


@pytest.mark.parametrize(
    ("value", "stamp", "words"),
    [
        ([0.5], 1.0, "shape"),
        ([0.5, 0.5, 0.5], 1.0, "shape"),
        (["a", "b"], 1.0, "real numbers"),
        ([0.5, math.nan], 1.0, "not finite"),
        ([0.5, math.inf], 1.0, "not finite"),
        ([0.5, 1.5], 1.0, "outside"),
        ([-0.1, 0.5], 1.0, "outside"),
        ([0.5, 0.5], 0.5, "older"),
        ([0.5, 0.5], math.nan, "older"),
        ([0.5, 0.5], 10**400, "older"),
        ([0.5, 0.5], "1.0", "older"),
        (None, 1.0, "real numbers"),
    ],
)
def test_bad_readings_are_rejected_with_a_reason(value: object, stamp: object, words: str) -> None:
    valid, why = SPEC.check(Reading(value, stamp), 1.0)  # type: ignore[arg-type]
    assert valid is None and words in why


def test_an_object_without_value_is_rejected() -> None:
    assert SPEC.check(object(), 1.0)[0] is None


@pytest.mark.parametrize(
    "kwargs",
    [{"shape": (0,)}, {"shape": [2]}, {"lower": 1.0, "upper": 0.0}, {"max_age": 0.0}, {"update_interval": math.nan},
     {"delay": -1.0}],
)
def test_a_bad_spec_is_refused(kwargs: dict) -> None:
    base = {"name": "x", "shape": (1,)}
    with pytest.raises(ValueError):
        InputSpec(**{**base, **kwargs})


def test_real_array_and_fresh_stamp() -> None:
    assert real_array([True, False]) is None and real_array("abc") is None and real_array([[1], [1, 2]]) is None
    assert real_array([1, 2]) is not None
    assert fresh_stamp(1.0, 1.05, 0.1) and not fresh_stamp(1.0, 1.2, 0.1) and not fresh_stamp(True, 1.0, 0.1)


def test_real_array_hands_on_a_float64_array_with_an_equal_dtype_of_its_own_as_it_is() -> None:
    """Arrays from numba's cached kernels (the controller's reference, checked by the supervisor every cycle)
    carry a float64 dtype equal to numpy's but not the same object, as an unpickled dtype does: no copy."""
    own = pickle.loads(pickle.dumps(np.dtype(np.float64)))
    a = np.empty(7, dtype=own)
    a[:] = 1.0
    assert a.dtype is own and own is not np.dtype(np.float64)
    assert real_array(a) is a


def test_the_fast_path_predicate_takes_only_c_contiguous_float64_arrays_of_any_float64_dtype_object() -> None:
    own = pickle.loads(pickle.dumps(np.dtype(np.float64)))
    a = np.ones(7, dtype=own)
    assert is_f64_c(a) and as_f64_c(a) is a  # an equal dtype of its own (numba's cached kernels): no copy
    strided = np.ones(14)[::2]
    for x in (strided, np.ones(7, dtype=np.float32), [1.0, 2.0], np.ones((3, 3)).T):
        assert not is_f64_c(x)
        y = as_f64_c(x)
        assert is_f64_c(y) and np.array_equal(y, np.asarray(x, dtype=float))
