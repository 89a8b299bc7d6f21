"""``exp`` of a non-positive number without a library call, so that a loop over it vectorises
(compiled without fast-math flags, so that the compiler keeps the reduction exact, and
inlined by LLVM into the kernels that call it).

The kernels weigh every state by ``exp(score - best)``: a few thousand exponentials per frame,
each a call into the C library (about 10 ns) that also keeps the loop around it from being
vectorised. ``exp_nonpositive`` is the textbook reduction ``x = n ln 2 + r``, ``|r| <= ln 2 / 2``
(``ln 2`` split in two parts, so that ``r`` is exact to the last bit), a degree-13 Taylor
polynomial of ``exp(r)`` (truncation below 1e-17 relative) and ``2**n`` built from its bits:
within 2 units in the last place of ``math.exp`` for x in [-708, 0], exactly 0 below -708
(``math.exp`` gives subnormal numbers there; nothing the kernels weigh is that small relative
to the best state).
"""
import math

from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from followers._jit import plain

_LOG2E = 1.4426950408889634
_LN2_HI = 0.6931471803691238     # the upper 32 bits of ln 2: n * _LN2_HI is exact
_LN2_LO = 1.9082149292705877e-10  # ln 2 - _LN2_HI
_LOWEST = -708.0                  # exp(-708) = 3.3e-308, the last normal result


@intrinsic
def _bits_as_float(typingctx, bits):
    """The float64 whose IEEE bits are the int64 ``bits``."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())
    return types.float64(types.int64), codegen


@plain
def exp_nonpositive(x):
    """``exp(x)`` for ``x <= 0`` (-inf gives 0); see the module's note for its accuracy."""
    low = x < _LOWEST
    x = max(x, _LOWEST)
    n = math.floor(x * _LOG2E + 0.5)
    r = (x - n * _LN2_HI) - n * _LN2_LO
    p = 1.0 / 6227020800.0
    p = p * r + 1.0 / 479001600.0
    p = p * r + 1.0 / 39916800.0
    p = p * r + 1.0 / 3628800.0
    p = p * r + 1.0 / 362880.0
    p = p * r + 1.0 / 40320.0
    p = p * r + 1.0 / 5040.0
    p = p * r + 1.0 / 720.0
    p = p * r + 1.0 / 120.0
    p = p * r + 1.0 / 24.0
    p = p * r + 1.0 / 6.0
    p = p * r + 0.5
    p = p * r + 1.0
    p = p * r + 1.0
    scale = _bits_as_float((int(n) + 1023) << 52)
    return 0.0 if low else p * scale
