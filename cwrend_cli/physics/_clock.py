"""A monotonic clock that compiled code reads (private; the closed loop's re-solve timing).

The closed loop's warm re-solves run inside compiled code (issue 17) and
each records its wall time, as :func:`time.perf_counter` gives it to the
Python path. :func:`monotonic_s` is that clock inside ``@njit`` code:

* where the C library has ``clock_gettime`` (Linux, macOS, the BSDs:
  ``time.CLOCK_MONOTONIC`` exists), a direct call of
  ``clock_gettime(CLOCK_MONOTONIC, …)`` emitted into the compiled code
  (about 40 ns a reading, measured; the clock ``time.monotonic`` reads, so the
  wall times are comparable with Python's). It refers to the C function by
  name only, so the functions using it stay in numba's on-disk cache;
* elsewhere (Windows), ``time.perf_counter`` read in object mode
  (:func:`_perf_counter_objmode`, about 1.5 µs a reading).

Resolution is the clock's (1 ns nominal). Only differences of two readings
mean anything.
"""

from __future__ import annotations

import ctypes
import time
from typing import Any

from llvmlite import ir
from numba import njit, objmode, types
from numba.core import cgutils
from numba.extending import intrinsic

#: ``CLOCK_MONOTONIC`` of this platform's C library; None where there is no ``clock_gettime``.
CLOCK_ID: int | None = getattr(time, "CLOCK_MONOTONIC", None)


def _register_clock_gettime() -> bool:
    """Make ``clock_gettime`` of the running C library known to the JIT linker by name."""
    import llvmlite.binding as llvm

    try:
        libc = ctypes.CDLL(None)
        address = ctypes.cast(libc.clock_gettime, ctypes.c_void_p).value
    except (OSError, AttributeError, TypeError):
        return False
    if address is None:
        return False
    llvm.add_symbol("clock_gettime", address)
    return True


HAVE_CLOCK_GETTIME: bool = CLOCK_ID is not None and _register_clock_gettime()


@intrinsic
def _clock_gettime_ns(typingctx: Any) -> tuple[Any, Any]:
    """``clock_gettime(CLOCK_ID, &ts)`` as ``ts.tv_sec·10⁹ + ts.tv_nsec`` [ns] (int64)."""
    sig = types.int64()

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        i32, i64 = ir.IntType(32), ir.IntType(64)
        timespec = ir.LiteralStructType([i64, i64])  # time_t tv_sec; long tv_nsec (LP64)
        fnty = ir.FunctionType(i32, [i32, timespec.as_pointer()])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "clock_gettime")  # type: ignore[no-untyped-call]
        # in the entry block (not at the call): safe inside loops
        ts = cgutils.alloca_once(builder, timespec)  # type: ignore[no-untyped-call]
        builder.call(fn, [ir.Constant(i32, CLOCK_ID), ts])
        zero = ir.Constant(i32, 0)
        sec = builder.load(builder.gep(ts, [zero, zero]))
        nsec = builder.load(builder.gep(ts, [zero, ir.Constant(i32, 1)]))
        return builder.add(builder.mul(sec, ir.Constant(i64, 1_000_000_000)), nsec)

    return sig, codegen


@njit(cache=True)
def _clock_gettime_s() -> float:
    """Seconds of ``CLOCK_MONOTONIC`` (see the module docstring)."""
    return _clock_gettime_ns() * 1e-9  # type: ignore[call-arg]  # typingctx: numba passes it


@njit(cache=True)
def _perf_counter_objmode() -> float:
    """:func:`time.perf_counter` [s], read in object mode (the portable fallback)."""
    with objmode(t="float64"):
        t = time.perf_counter()
    return t


#: The compiled clock [s]: call it from ``@njit`` code (or Python) as ``monotonic_s()``.
monotonic_s = _clock_gettime_s if HAVE_CLOCK_GETTIME else _perf_counter_objmode
