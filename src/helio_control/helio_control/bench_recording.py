"""
Benchmark of the bag writer: ``python -m helio_control.bench_recording --json PATH``.

How fast ``bag_files.BagWriter`` takes camera frames (serialized sensor_msgs/Image, as the
recorder receives them) and closes zstd chunks, against what the cameras send: the simulated
RGB camera's 640 x 480 rgb8 frames (0.92 MB) and the thermal camera's 160 x 120 16UC1 frames.
Frames are the simulated world's kind of picture (a smooth panel with sensor noise, which
decides how well zstd compresses) made in code; numpy is pinned to one thread.
Run it under ``flock /tmp/helio-bench.lock`` on a shared machine.
"""

import argparse
import os
import shutil
import sys
import tempfile
import time

from helio_control.bag_files import BagWriter, qos_profile_dict, TopicInfo
from helio_optics.bench_report import add_json_option, report
from helio_optics.node_kit.conversions import numpy_to_image
import numpy as np
from rclpy.serialization import serialize_message


def camera_frames(count, height, width, encoding, seed=0):
    """Return `count` serialized Image frames of a noisy smooth scene."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width]
    scene = 120.0 + 60.0 * np.sin(x / 40.0) * np.cos(y / 55.0)
    frames = []
    for _ in range(count):
        noisy = scene + rng.normal(0.0, 2.0, scene.shape)         # sim_world noise_sigma 2
        if encoding == 'rgb8':
            array = np.repeat(np.clip(noisy, 0, 255).astype(np.uint8)[..., None], 3, axis=2)
        else:                                                     # centikelvin, ~25 degC
            array = (29815 + 10 * noisy).astype(np.uint16)
        frames.append(serialize_message(numpy_to_image(array, encoding)))
    return frames


def write_rate(frames, compression, directory, chunk_size=4 << 20):
    """Write `frames` into a fresh bag; return (frames/s, MB/s in, compressed/raw ratio)."""
    shutil.rmtree(directory, ignore_errors=True)
    writer = BagWriter(directory, chunk_size=chunk_size, chunk_period=1e9,
                       compression=compression)
    writer.add_topic(TopicInfo('/camera/image_raw', 'sensor_msgs/msg/Image',
                               [qos_profile_dict(reliability='best_effort')]))
    started = time.perf_counter()
    for index, frame in enumerate(frames):
        writer.write('/camera/image_raw', index * 10**8, frame)
    writer.close()
    elapsed = time.perf_counter() - started
    raw = sum(len(frame) for frame in frames)
    return len(frames) / elapsed, raw / elapsed / 1e6, os.path.getsize(writer.path) / raw


def main(args=None):
    """Measure, print, and write the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    add_json_option(parser)
    parser.add_argument('--frames', type=int, default=60, help='frames per measurement')
    arguments = parser.parse_args(args)
    from threadpoolctl import threadpool_limits
    figures = {}
    with threadpool_limits(1), tempfile.TemporaryDirectory(prefix='helio_bench_') as work:
        for name, shape, encoding in (('rgb_640x480', (480, 640), 'rgb8'),
                                      ('thermal_160x120', (120, 160), '16UC1')):
            frames = camera_frames(arguments.frames, *shape, encoding)
            for compression in ('zstd', 'none'):
                rate, throughput, ratio = write_rate(frames, compression,
                                                     os.path.join(work, 'bag'))
                figures[f'write_{name}_{compression}_frames_per_s'] = rate
                figures[f'write_{name}_{compression}_mb_per_s'] = throughput
                figures[f'write_{name}_{compression}_size_ratio'] = ratio
    return report(figures, arguments.json)


if __name__ == '__main__':
    sys.exit(main())
