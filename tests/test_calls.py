"""Calls of a compiled kernel by its address (cwrend_cli.physics._calls; issue 37 item 12).

A kernel that calls another through a handle is compiled without it and gets
what a direct call gives, exceptions included.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from numba import njit, types
from numba.core import errors

from cwrend_cli.physics import _calls

_VEC = types.float64[::1]
_RETURNS = types.Tuple((types.float64, types.int64))


def _callee() -> Any:
    @njit
    def weighted(x: float, a: np.ndarray) -> tuple[float, int]:
        if x < 0.0:
            raise ValueError("negative weight")
        s = 0.0
        for v in a:
            s += np.sin(v * x)
        return s, a.shape[0]

    return weighted


def _caller() -> Any:
    @njit
    def twice(fn: Any, x: float, a: np.ndarray) -> float:
        s1, n1 = _calls.call(fn, (x, a))
        s2, n2 = _calls.call(fn, (x + 1.0, a))
        return s1 * n1 + s2 * n2

    return twice


def test_a_call_by_handle_gives_what_a_direct_call_gives() -> None:
    callee = _callee()
    caller = _caller()
    a = np.linspace(0.1, 2.0, 7)

    @njit
    def direct(x: float, a: np.ndarray) -> float:
        s1, n1 = callee(x, a)
        s2, n2 = callee(x + 1.0, a)
        return s1 * n1 + s2 * n2

    fn = _calls.handle(callee, (types.float64, _VEC), _RETURNS)
    assert caller(fn, 0.3, a) == direct(0.3, a)  # bit for bit: the same machine code


def test_an_exception_of_the_callee_is_raised_by_the_caller() -> None:
    callee = _callee()
    fn = _calls.handle(callee, (types.float64, _VEC), _RETURNS)
    with pytest.raises(ValueError, match="negative weight"):
        _caller()(fn, -2.0, np.ones(3))


def test_the_caller_compiles_without_the_callee() -> None:
    callee = _callee()
    caller = _caller()
    sig = (_calls.handle_type((types.float64, _VEC), _RETURNS), types.float64, _VEC)
    caller.compile(sig)
    assert callee.signatures == []  # not compiled, not linked into the caller


def test_a_call_with_other_argument_types_is_a_typing_error() -> None:
    caller = _caller()
    sig = (_calls.handle_type((types.float64, types.float64[:]), _RETURNS), types.float64, _VEC)
    with pytest.raises(errors.TypingError, match="call of"):
        caller.compile(sig)  # the handle's array is of any layout, the caller's contiguous


def test_a_handle_of_a_kernel_returning_another_type_is_refused() -> None:
    with pytest.raises(TypeError, match="returns"):
        _calls.handle(_callee(), (types.float64, _VEC), types.float64)
