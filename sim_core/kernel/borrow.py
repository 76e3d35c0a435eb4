"""Borrowed array views for the compiled kernel's hot loop.

numba reference-counts every array: each array handed to an inlined helper is increfed on entry and
decrefed on exit, with atomic instructions. Nested helpers put other decrefs between each pair, so
numba's reference-count pruning cannot remove them, and in the plant step they cost about as much as
the physics. ``borrow`` gives a view of the same memory without an owner (a null ``meminfo``): its
reference counting is a null check that LLVM folds away. Safe only where the views do not outlive
the call that borrowed them: the caller keeps the arrays alive for the duration of the call, and the
views are neither returned nor stored.
"""

from numba.core import cgutils, types
from numba.extending import intrinsic


def _unowned(context, builder, ty, value):
    if isinstance(ty, types.Array):
        ary = context.make_array(ty)(context, builder, value=value)
        ary.meminfo = cgutils.get_null_value(ary.meminfo.type)
        return ary._getvalue()
    if isinstance(ty, types.BaseTuple):
        items = cgutils.unpack_tuple(builder, value, len(ty))
        return context.make_tuple(builder, ty, [_unowned(context, builder, t, v) for t, v in zip(ty, items)])
    return value


@intrinsic
def borrow(typingctx, x):
    """``x`` (an array, or a (named) tuple of arrays and other values) with every array unowned."""
    def codegen(context, builder, sig, args):
        return _unowned(context, builder, sig.args[0], args[0])
    return x(x), codegen
