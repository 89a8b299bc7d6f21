"""The numba settings of every per-frame kernel.

- ``fastmath={"reassoc", "contract"}``: the compiler may reassociate sums and fuse
  multiply-adds (vectorised emission loops), but not assume away NaN or inf: -inf marks "no
  state yet" and an overflow check compares against inf.
- ``_nrt=False``: no reference counting. The kernels allocate nothing per frame (every array
  is made by the model or the state, in Python); without it, each read of an array from a
  model or state named tuple would cost a pair of atomic reference-count updates, which in
  the per-row loops cost more than the arithmetic.
- ``cache=True``: compiled once per installation; a fresh process loads them from the cache.
- ``inline``: stages inlined into the kernel that calls them (numba's own inliner), so that a
  stage is a function of a few structured arguments at no cost per call.
- ``entry``: a kernel's compiled function for fixed argument types, called per frame without
  the dispatcher's type resolution (about 30 us for named tuples of arrays, more than a small
  bank's whole step).
"""
import numba as nb

FAST = {"reassoc", "contract"}
kernel = nb.njit(cache=True, fastmath=FAST, _nrt=False)
# set-up work that must give exactly NumPy's results (no fused multiply-adds)
plain = nb.njit(cache=True, _nrt=False)
inline = nb.njit(cache=True, fastmath=FAST, _nrt=False, inline="always")


def entry(dispatcher, *args):
    """``dispatcher``'s compiled function for the types of ``args`` (compiled or loaded from the
    cache now), to be called with arguments of exactly those types: it does not check them."""
    return dispatcher.compile(tuple(nb.typeof(a) for a in args))
