#!/usr/bin/env python3
"""
Deal the packages, or the system test files, into lanes of about equal test time.

    test_lanes.py LANES NAME...

A NAME is a package or a test file (its path; weighed by its module name); one lane is
printed per line. The weights are the test times of a fresh clone's run of the suite (2-core
machine, seconds: the packages in s42e, the system test modules in s43c); a name not listed
weighs 1. Longest first, each to the lightest lane (the greedy rule, within 4/3 of the best
split). Only the standard library: it runs before anything is set up.
"""

import os
import sys

TEST_SECONDS = {
    'helio_drivers': 98, 'helio_control': 65, 'helio_optics': 64, 'helio_perception': 40,
    'helio_msgs': 3,
    'test_painter': 242, 'test_painter_safety': 185, 'test_operator_tools': 106,
    'test_lens_planner': 78, 'test_sweep_over_suns': 77, 'test_lepton_camera': 66,
    'test_doctor': 64, 'test_recording': 40, 'test_replay_regression': 35,
    'test_graph_estimates_the_sun': 27, 'test_calibrations_persist': 10,
    'test_sim_webcam_spot': 10, 'test_driver_services': 10, 'test_frozen_world': 9,
    'test_marker_under_shadow': 5}


def weight(name):
    """Return the usual test time of a package or a test file [s] (1 if unknown)."""
    return TEST_SECONDS.get(os.path.splitext(os.path.basename(name))[0], 1)


def lanes_of(names, count):
    """Return `count` lists of `names`, the heaviest first, each to the lightest lane."""
    lanes = [[] for _ in range(max(1, count))]
    loads = [0] * len(lanes)
    for name in sorted(names, key=lambda name: -weight(name)):
        lightest = loads.index(min(loads))
        lanes[lightest].append(name)
        loads[lightest] += weight(name)
    return [lane for lane in lanes if lane]


def main(args=None):
    """Print the lanes of the command line's names, one per line."""
    args = sys.argv[1:] if args is None else args
    if not args or not args[0].isdigit():
        sys.exit('usage: test_lanes.py LANES NAME...')
    for lane in lanes_of(args[1:], int(args[0])):
        print(' '.join(lane))


if __name__ == '__main__':
    main()
