"""The Numba decorators every kernel module uses.

``cache=True`` keeps compiled code between runs; ``error_model="numpy"`` makes a division by zero
give inf/NaN (caught by the kernels' own checks) instead of raising inside a loop; ``nogil=True``
lets Python threads run kernels side by side. No fastmath: the kernels' NaN checks must survive
compilation. Importing this module sets up the threading layer first (see :mod:`occmap._threads`).
"""

from numba import njit

from ._threads import prefer_tbb

prefer_tbb()

kernel = njit(cache=True, error_model="numpy", nogil=True)
kernel_parallel = njit(cache=True, error_model="numpy", nogil=True, parallel=True)

#: For small helpers that take arrays and run in hot loops: Numba inlines them into each caller
#: (a call passing arrays costs ~25 ns of reference counting, more than such a helper's work).
inline_kernel = njit(cache=True, error_model="numpy", nogil=True, inline="always")
