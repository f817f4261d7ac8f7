"""
Keep freed memory in the process (glibc), so the world's big arrays are not page-faulted in.

Every world step and camera frame allocates and frees arrays of 0.3-4 MB (the heat patch is
81 000 doubles, an RGB frame's light 921 600 floats). glibc serves blocks above its mmap
threshold with a fresh ``mmap`` and hands them back to the kernel on ``free``; the next
allocation then page-faults every page in again and the kernel zeroes it. Measured here,
that made a tridiagonal product over the patch cost 0.9-1.1 ms instead of 0.3 ms (the
rest was system time). ``keep_freed_memory`` raises the mmap and trim thresholds with
``mallopt`` once per process, so such blocks are reused from the heap. On a C library
without ``mallopt`` it does nothing.
"""

import ctypes

M_TRIM_THRESHOLD = -1      # glibc's malloc.h
M_MMAP_THRESHOLD = -3
_DONE = {'done': False, 'applied': False}


def keep_freed_memory(mmap_threshold=64 << 20, trim_threshold=256 << 20):
    """
    Serve blocks below `mmap_threshold` bytes from the heap and keep `trim_threshold` free.

    Returns True when the C library took the settings (once per process; later calls
    return the first call's answer).
    """
    if not _DONE['done']:
        _DONE['done'] = True
        try:
            mallopt = ctypes.CDLL(None).mallopt
        except (AttributeError, OSError):
            return False
        mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
        mallopt.restype = ctypes.c_int
        _DONE['applied'] = bool(mallopt(M_MMAP_THRESHOLD, int(mmap_threshold))
                                and mallopt(M_TRIM_THRESHOLD, int(trim_threshold)))
    return _DONE['applied']
