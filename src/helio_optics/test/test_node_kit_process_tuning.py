"""Tests of the nodes' process-wide settings (glibc malloc, gc.freeze, one-thread numerics)."""

import gc
import json
import os
import resource
import subprocess
import sys
import weakref

from helio_optics.node_kit.process_tuning import (
    frozen_after_start_up, keep_large_buffers, MMAP_THRESHOLD_MAX, single_threaded_numerics)
import numpy as np
import pytest

PAGE = resource.getpagesize()
FRAME = 640 * 480 * 3  # one 640x480 rgb8 frame [B]


def minor_faults():
    """Return this thread's minor page faults so far."""
    return resource.getrusage(resource.RUSAGE_THREAD).ru_minflt


def frame_pipeline():
    """Allocate what one frame does in spot_detector: a frame, its copy, grey images."""
    frame = np.ones(FRAME, np.uint8)
    copy = bytes(frame)
    gray = np.ones(FRAME // 3, np.uint8)
    blurred = gray + 1
    return len(copy) + int(blurred[-1])


def test_freed_frame_buffers_are_reused_without_page_faults():
    # a fresh mapping faults once per page it touches (the independent truth): about
    # 2 * (FRAME + FRAME / 3) / PAGE = 600 faults per frame when glibc unmaps freed buffers
    pages_per_frame = 2 * (FRAME + FRAME // 3) // PAGE
    if not keep_large_buffers():
        pytest.fail('mallopt is not available: this C library is not glibc')
    frame_pipeline()  # the heap grows once
    before = minor_faults()
    for _ in range(20):
        frame_pipeline()
    per_frame = (minor_faults() - before) / 20
    assert per_frame < 0.1 * pages_per_frame


@pytest.mark.parametrize('mmap_threshold, trim_threshold', [
    (0, 2 * MMAP_THRESHOLD_MAX),
    (MMAP_THRESHOLD_MAX + 1, 4 * MMAP_THRESHOLD_MAX),
    (1 << 20, 1 << 19),
])
def test_out_of_range_thresholds_are_refused(mmap_threshold, trim_threshold):
    with pytest.raises(ValueError, match='threshold'):
        keep_large_buffers(mmap_threshold, trim_threshold)


class Built:
    """Stands for a node class: the object built, holding a reference cycle."""

    def __init__(self):
        self.cycle = [self]


def test_start_up_objects_are_frozen_after_building():
    build = frozen_after_start_up(Built)
    assert build.__name__ == 'Built'
    try:
        gc.unfreeze()
        made = build()
        assert isinstance(made, Built)
        # the object built is in the permanent generation: no collection walks it
        assert gc.get_freeze_count() > 0
        assert not any(obj is made for obj in gc.get_objects())
    finally:
        gc.unfreeze()
    assert any(obj is made for obj in gc.get_objects())


def test_garbage_from_before_building_is_collected_not_frozen():
    try:
        gc.unfreeze()
        garbage = Built()
        alive = weakref.ref(garbage)
        del garbage  # an unreachable cycle: only the collector frees it
        frozen_after_start_up(Built)()
        assert alive() is None
    finally:
        gc.unfreeze()


def test_numerics_are_pinned_to_one_thread_here_and_in_libraries_loaded_later():
    # a fresh interpreter: numpy loaded first (as a console script does), SciPy after
    script = (
        'import numpy, json\n'
        'from helio_optics.node_kit.process_tuning import single_threaded_numerics\n'
        'single_threaded_numerics()\n'
        'import os, scipy.linalg, cv2\n'
        'from threadpoolctl import threadpool_info\n'
        'print(json.dumps({"pools": [p["num_threads"] for p in threadpool_info()],\n'
        '                  "opencv": cv2.getNumThreads(),\n'
        '                  "omp": os.environ["OMP_NUM_THREADS"]}))\n')
    done = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    figures = json.loads(done.stdout)
    assert figures['pools'] and set(figures['pools']) == {1}
    assert figures['opencv'] == 1 and figures['omp'] == '1'


def test_a_real_node_process_logs_its_numerics_on_one_thread(tmp_path):
    from ament_index_python.packages import get_package_prefix
    executable = os.path.join(get_package_prefix('helio_optics'), 'lib', 'helio_optics',
                              'sun_estimator')
    process = subprocess.Popen([executable, '--ros-args', '-r', '__ns:=/numerics_test'],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        line = ''
        for line in process.stdout:
            if 'numeric thread pools' in line:
                break
        pools = line.split('numeric thread pools: ', 1)[1].strip().split(', ')
        assert pools and all(pool.rsplit(' ', 1)[1] == '1' for pool in pools), line
        assert any(pool.startswith('opencv') for pool in pools)
    finally:
        process.terminate()
        process.wait(30)


def test_a_thread_count_below_one_is_refused():
    with pytest.raises(ValueError, match='>= 1'):
        single_threaded_numerics(0)
