"""Memory ordering for the shared block, compiled: acquire loads, release stores, fences and the
seqlock built on them.

The service and the engine process share one block of memory. A reader must never act on a
half-written command table or state snapshot. x86 keeps stores in program order (TSO), but ARM
(Jetson, Raspberry Pi 4/5, Graviton) does not: without barriers a reader can see the new sequence
number before the data it guards. These helpers emit LLVM's atomic loads/stores and fences through
numba, so the same source is correct on both (a compiler barrier on x86, ``dmb ish`` on ARM64).

Seqlock (one writer per area; writers of one area in the service hold a lock among themselves):

* writer: ``seq`` odd (relaxed store), release fence, data, ``seq`` even (release store)
* reader: ``s0`` = acquire load; odd -> retry; copy; acquire fence; ``s1`` = relaxed load;
  ``s0 == s1`` -> the copy is consistent. After ``tries`` failures the reader says so (False):
  the caller counts it and never uses the copy.
"""

from __future__ import annotations

import platform
import sys

import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

_NJ = dict(cache=True, nogil=True)


def _item_pointer(context, builder, sig, args):
    aryty = sig.args[0]
    ary = context.make_array(aryty)(context, builder, args[0])
    idx = context.cast(builder, args[1], sig.args[1], types.intp)
    return cgutils.get_item_pointer(context, builder, aryty, ary, [idx], wraparound=False)


def _is_i64_array(arr) -> bool:
    return isinstance(arr, types.Array) and arr.dtype == types.int64 and arr.ndim == 1


@intrinsic
def _load(typingctx, arr, idx, order):
    if not _is_i64_array(arr) or not isinstance(order, types.StringLiteral):
        return None
    ordering = order.literal_value

    def codegen(context, builder, sig, args):
        return builder.load_atomic(_item_pointer(context, builder, sig, args), ordering, 8)

    return types.int64(arr, idx, order), codegen


@intrinsic
def _store(typingctx, arr, idx, value, order):
    if not _is_i64_array(arr) or not isinstance(order, types.StringLiteral):
        return None
    ordering = order.literal_value

    def codegen(context, builder, sig, args):
        val = context.cast(builder, args[2], sig.args[2], types.int64)
        builder.store_atomic(val, _item_pointer(context, builder, sig, args), ordering, 8)
        return context.get_dummy_value()

    return types.void(arr, idx, value, order), codegen


@intrinsic
def _fetch_add(typingctx, arr, idx, value):
    if not _is_i64_array(arr):
        return None

    def codegen(context, builder, sig, args):
        val = context.cast(builder, args[2], sig.args[2], types.int64)
        return builder.atomic_rmw("add", _item_pointer(context, builder, sig, args), val, "acq_rel")

    return types.int64(arr, idx, value), codegen


@intrinsic
def _fence(typingctx, order):
    if not isinstance(order, types.StringLiteral):
        return None
    ordering = order.literal_value

    def codegen(context, builder, sig, args):
        builder.fence(ordering)
        return context.get_dummy_value()

    return types.void(order), codegen


@njit(**_NJ)
def load_acquire(words, i):
    return _load(words, i, "acquire")


@njit(**_NJ)
def load_relaxed(words, i):
    return _load(words, i, "monotonic")


@njit(**_NJ)
def store_release(words, i, value):
    _store(words, i, value, "release")


@njit(**_NJ)
def fetch_add(words, i, value):
    """Atomic ``words[i] += value``; returns the previous value."""
    return _fetch_add(words, i, value)


@njit(**_NJ)
def fence_acquire():
    _fence("acquire")


@njit(**_NJ)
def fence_release():
    _fence("release")


@njit(**_NJ)
def write_begin(words, i):
    """Start writing the area guarded by ``words[i]`` (single writer at a time)."""
    s = _load(words, i, "monotonic")
    _store(words, i, s + 1, "monotonic")
    _fence("release")


@njit(**_NJ)
def write_end(words, i):
    s = _load(words, i, "monotonic")
    _store(words, i, s + 1, "release")


@njit(**_NJ)
def read_consistent(words, i, area, out, tries):
    """Copy the 1-D ``area`` into ``out`` as one consistent snapshot. True on success; False
    after ``tries`` attempts that all raced a writer (``out`` then holds garbage and must not be
    used)."""
    for _ in range(tries):
        s0 = _load(words, i, "acquire")
        if s0 & 1:
            continue
        for k in range(area.shape[0]):
            out[k] = area[k]
        _fence("acquire")
        if _load(words, i, "monotonic") == s0:
            return True
    return False


class SharedMemoryUnsupported(RuntimeError):
    """This host cannot run the shared-memory protocol correctly; the service refuses to start."""


def platform_problem(machine: str, pointer_bits: int) -> str | None:
    """Why the shared block cannot be used on this kind of host, or None. Needs a 64-bit
    platform: float64 statistics are read without a lock, which is only safe where an aligned
    8-byte access is single-copy atomic (every 64-bit ISA; not armv7 or i686)."""
    if pointer_bits < 64:
        return (f"HydroHIL needs a 64-bit platform for its shared memory (this is a {pointer_bits}-bit "
                f"{machine or 'unknown'} build); use a 64-bit OS (e.g. Raspberry Pi OS 64-bit, aarch64)")
    return None


def check_platform() -> None:
    """Refuse clearly where the protocol cannot be correct, and compile and exercise the helpers
    once (a host whose LLVM cannot emit 8-byte atomics fails here, not in the loop)."""
    problem = platform_problem(platform.machine(), 64 if sys.maxsize > 2**32 else 32)
    if problem:
        raise SharedMemoryUnsupported(problem)
    try:
        words = np.zeros(2, dtype=np.int64)
        area = np.arange(4.0)
        out = np.zeros(4)
        write_begin(words, 0)
        odd = load_acquire(words, 0)
        write_end(words, 0)
        ok = read_consistent(words, 0, area, out, 2)
        store_release(words, 1, 7)
        fetch_add(words, 1, 3)
        fence_acquire()
        fence_release()
    except Exception as exc:  # noqa: BLE001 - any compile/run failure means: not supported here
        raise SharedMemoryUnsupported(f"the shared-memory barriers cannot be compiled on "
                                      f"{platform.machine()}: {exc}") from None
    if not (odd == 1 and ok and load_relaxed(words, 0) == 2 and words[1] == 10 and np.array_equal(out, area)):
        raise SharedMemoryUnsupported(f"the shared-memory barriers misbehave on {platform.machine()}")
