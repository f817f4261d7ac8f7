"""
Process-wide settings for a node that handles camera frames at a steady rate.

Two causes of per-frame latency that are not in the algorithms, measured on spot_detector
with 640x480 rgb8 images at 30 Hz (README, "End-to-end latency"):

- Large buffers. Every frame allocates several buffers of 0.3-0.9 MB (the message taken from
  DDS, its Python copy, the grey image, the blurred and binary images). glibc serves them
  with fresh mmap()s and gives the pages back on free, so each frame page-faults its buffers
  in again: about 560 minor faults and 1.3 ms per frame in the node. `keep_large_buffers`
  raises glibc's mmap and trim thresholds (mallopt) so that freed buffers stay mapped and
  are reused.
- Numeric thread pools. numpy's BLAS (OpenBLAS) and OpenCV start one worker per core; on
  two shared cores the world's heat solver and the nodes' frame work then fight each other
  (a heat step 15-28 ms instead of 3 ms under load), and multi-thread BLAS results differ
  in the last bits from run to run. `single_threaded_numerics` pins them to one thread.
- Start-up objects. After imports (rclpy, numpy, OpenCV, SciPy) the collector tracks about
  60 000 objects; a full (generation 2) collection walks them all, about 35 ms here.
  `frozen_after_start_up` collects once after the node is built and moves the survivors to
  the permanent generation (gc.freeze), so a later full collection only walks what the node
  allocated since.

No rclpy import: the nodes' main() call these, tests call them directly.
"""

import ctypes
import gc
import os

M_TRIM_THRESHOLD = -1  # mallopt parameters, glibc's malloc.h
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_MAX = 4 * 1024 * 1024 * ctypes.sizeof(ctypes.c_long)  # glibc's upper bound [B]


def keep_large_buffers(mmap_threshold=MMAP_THRESHOLD_MAX, trim_threshold=2 * MMAP_THRESHOLD_MAX):
    """
    Let glibc reuse freed large buffers instead of unmapping them (mallopt).

    Allocations below `mmap_threshold` [B] come from the heap, and up to `trim_threshold` [B]
    of free memory at its top is kept rather than returned to the system. The defaults
    (32 MiB and 64 MiB on 64-bit) cover a 1920x1080 rgb8 frame (6.2 MB) several times over.
    Return True when both were applied, False when the C library has no mallopt (not
    glibc: nothing changes). Raise ValueError on a threshold out of glibc's range.
    """
    if not 0 < mmap_threshold <= MMAP_THRESHOLD_MAX:
        raise ValueError(f'mmap_threshold {mmap_threshold} B is outside (0, '
                         f'{MMAP_THRESHOLD_MAX}] (glibc ignores larger values)')
    if trim_threshold < mmap_threshold:
        raise ValueError(f'trim_threshold {trim_threshold} B is below mmap_threshold '
                         f'{mmap_threshold} B: freed buffers would be given back at once')
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, int(mmap_threshold))) and \
        bool(mallopt(M_TRIM_THRESHOLD, int(trim_threshold)))


def frozen_after_start_up(factory):
    """
    Return a callable that builds `factory()`, then collects and freezes the survivors.

    For ``run_node(frozen_after_start_up(SpotDetectorNode), args)``: everything alive once
    the node is constructed (modules, the node, its parameters) goes to the collector's
    permanent generation, so no later collection walks it again.
    """
    def build():
        made = factory()
        gc.collect()
        gc.freeze()
        return made
    build.__name__ = getattr(factory, '__name__', 'build')
    build.__doc__ = f'Build {build.__name__}, then collect and freeze the start-up objects.'
    return build


THREAD_VARIABLES = ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS',
                    'BLIS_NUM_THREADS', 'NUMEXPR_NUM_THREADS', 'VECLIB_MAXIMUM_THREADS')


def single_threaded_numerics(threads=None):
    """
    Pin numpy's BLAS/OpenMP pools and OpenCV to `threads` (HELIO_NUMERIC_THREADS, else 1).

    Three layers, because a console script has imported numpy before main() runs: the
    pools already loaded are limited through threadpoolctl; the environment variables
    cover libraries loaded later and child processes; OpenCV's own pool is set directly.
    Return {library: threads} as threadpoolctl then reports it (plus 'opencv').
    """
    if threads is None:
        threads = int(os.environ.get('HELIO_NUMERIC_THREADS', '1'))
    if threads < 1:
        raise ValueError(f'numeric threads must be >= 1, got {threads}')
    for name in THREAD_VARIABLES:
        os.environ[name] = str(threads)
    from threadpoolctl import threadpool_info, threadpool_limits
    threadpool_limits(limits=threads)
    pools = {f"{pool['internal_api']}:{os.path.basename(pool['filepath'])}": pool['num_threads']
             for pool in threadpool_info()}
    try:
        import cv2
    except ImportError:
        return pools
    cv2.setNumThreads(threads)
    pools['opencv'] = cv2.getNumThreads()
    return pools
