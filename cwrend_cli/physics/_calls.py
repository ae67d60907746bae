"""Calls of a compiled kernel by its address, from another kernel (private; issue 37 item 12).

numba links a kernel's whole call tree into every kernel that calls it, and
LLVM optimises and emits that tree again there: a caller compiles only after
its callees, and as long as they do. A kernel that takes a callee as a
:func:`handle` (its machine code's address and its numba signature, made in
Python) and calls it with :func:`call` is compiled without it: the callee
can be compiled before, after or in another process, and is compiled once.
The callee runs the machine code a direct call would (the same compiled
function, numba's calling convention, its exceptions raised in the caller),
so the numbers are the same.

numba's own first-class functions (``types.FunctionType`` arguments) do the
same, but take the address again at every call from Python (about 0.1 ms an
argument); a handle is two plain values.
"""

from __future__ import annotations

from typing import Any

from numba import types
from numba.core import cgutils, errors
from numba.extending import intrinsic

#: A handle: ``(address, signature)``, the signature a ``types.FunctionType`` (its numba
#: type in the caller: a tuple of an int64 and a type reference).
Handle = tuple[int, Any]


def handle(dispatcher: Any, args: tuple[Any, ...], returns: Any) -> Handle:
    """The handle of ``dispatcher`` compiled (or loaded) for the numba types ``args``.

    ``returns``: the numba type it must return (checked here: the caller is
    typed against the handle's signature, not the callee's code).
    """
    dispatcher.compile(args)
    done = dispatcher.overloads[tuple(args)]
    if done.signature.return_type != returns:
        raise TypeError(f"{dispatcher} returns {done.signature.return_type}, not {returns}")
    address = done.library.get_pointer_to_function(done.fndesc.llvm_func_name)
    return address, types.FunctionType(returns(*args))


def handle_type(args: tuple[Any, ...], returns: Any) -> Any:
    """The numba type of a :func:`handle` of a kernel of these argument and return types
    (to compile a caller without the callee)."""
    ref = types.TypeRef(types.FunctionType(returns(*args)))
    return types.Tuple((types.int64, ref))  # type: ignore[no-untyped-call]


@intrinsic
def call(typingctx: Any, fn: Any, args: Any) -> Any:
    """``fn``'s kernel called with the tuple ``args``; returns what it returns.

    ``fn``: a :func:`handle`. The arguments' types must be the handle's
    signature's, exactly (a typing error otherwise: the address is of code
    compiled for those types).
    """
    if not isinstance(fn, types.BaseTuple) or not isinstance(args, types.BaseTuple):
        return None
    parts: tuple[Any, ...] = tuple(fn.types) + tuple(args.types)  # type: ignore[attr-defined]
    sig = parts[1].instance_type.signature
    given = tuple(types.unliteral(t) for t in parts[2:])  # type: ignore[no-untyped-call]
    if given != tuple(sig.args):
        raise errors.TypingError(f"call of {sig} with {given}")
    returns = sig.return_type

    def codegen(context: Any, builder: Any, signature: Any, llargs: Any) -> Any:
        fn_v, args_v = llargs
        address = builder.extract_value(fn_v, 0)
        values = [builder.extract_value(args_v, i) for i in range(len(sig.args))]
        fnty = context.call_conv.get_function_type(returns, sig.args)
        callee = builder.inttoptr(address, fnty.as_pointer())
        status, out = context.call_conv.call_function(builder, callee, returns, sig.args, values)
        with cgutils.if_unlikely(builder, status.is_error):  # type: ignore[no-untyped-call]
            context.call_conv.return_status_propagate(builder, status)
        return out

    return returns(fn, args), codegen
