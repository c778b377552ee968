"""Borrowed array views: how the traffic kernels pass arrays without reference counting.

numba counts the references to an array's memory with atomic increments and decrements, a pair
per array and call of each ``inline="always"`` helper, which its pruning pass cannot remove once
the inlined branches merge them. A borrowed view has the same data, shape and strides but no
memory owner (a null ``meminfo``): borrowed at the top of the function whose body inlines the
helpers, the null is a constant there and LLVM folds every count away.

The rule that keeps it safe: a kernel borrows only its own arguments, at its top, and never
returns or stores the views (the caller holds the arguments until the kernel returns). An array
the kernel allocates itself must not be borrowed there: the name rebound to the view would release
the only reference.
"""

from __future__ import annotations

from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


def _borrow_one(context, builder, array_type, value):
    source = context.make_array(array_type)(context, builder, value=value)
    view = context.make_array(array_type)(context, builder)
    view.meminfo = cgutils.get_null_value(view.meminfo.type)
    view.parent = cgutils.get_null_value(view.parent.type)
    for field in ("nitems", "itemsize", "data", "shape", "strides"):
        setattr(view, field, getattr(source, field))
    return view._getvalue()


@intrinsic
def borrowed(typingctx, arrays):
    """``arrays`` (a tuple of arrays) as borrowed views, in a tuple (see the module's rule)."""
    if not isinstance(arrays, types.BaseTuple) or not all(isinstance(t, types.Array) for t in arrays):
        return None

    def codegen(context, builder, signature, args):
        views = [
            _borrow_one(context, builder, array_type, builder.extract_value(args[0], k))
            for k, array_type in enumerate(arrays)
        ]
        return context.make_tuple(builder, signature.return_type, views)

    return arrays(arrays), codegen
