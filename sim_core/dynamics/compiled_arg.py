"""Arrays as the compiled (numba) functions take them: C-contiguous and writable.

numba types a read-only array as a type of its own, so a read-only argument compiles the function
again, and for the kernel that is the whole kernel: a minute or more, and another copy in the cache.
Read-only arrays arrive without anyone asking for them: numpy arrays unpickled from Ray's object
store (a fleet's robot spec and records), views of a bytes buffer, memory maps. One signature
serves every caller when each argument passes through :func:`compiled_arg` (a copy only where the
array is read-only, not contiguous or of another dtype).
"""

from __future__ import annotations

import numpy as np


def compiled_arg(a, dtype=None) -> np.ndarray:
    """``a`` as a C-contiguous, writable array (of ``dtype`` if given); ``a`` itself when it is one."""
    out = np.ascontiguousarray(a, dtype=dtype)
    return out if out.flags.writeable else out.copy()
