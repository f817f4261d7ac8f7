#!/usr/bin/env python3
"""
Deal the packages to test into lanes of about equal test time; print one lane per line.

    test_lanes.py LANES PACKAGE...

The weights are the packages' colcon test times in a fresh clone's run of the suite (2-core
machine, s42e: seconds); a package not listed weighs 1. Longest first, each to the lightest
lane (the greedy rule, within 4/3 of the best split). Only the standard library: it runs
before anything is set up.
"""

import sys

TEST_SECONDS = {'helio_drivers': 98, 'helio_control': 65, 'helio_optics': 64,
                'helio_perception': 40, 'helio_msgs': 3}


def lanes_of(packages, count):
    """Return `count` lists of `packages`, the heaviest first, each to the lightest lane."""
    lanes = [[] for _ in range(max(1, count))]
    loads = [0] * len(lanes)
    for package in sorted(packages, key=lambda name: -TEST_SECONDS.get(name, 1)):
        lightest = loads.index(min(loads))
        lanes[lightest].append(package)
        loads[lightest] += TEST_SECONDS.get(package, 1)
    return [lane for lane in lanes if lane]


def main(args=None):
    """Print the lanes of the command line's packages, one per line."""
    args = sys.argv[1:] if args is None else args
    if not args or not args[0].isdigit():
        sys.exit('usage: test_lanes.py LANES PACKAGE...')
    for lane in lanes_of(args[1:], int(args[0])):
        print(' '.join(lane))


if __name__ == '__main__':
    main()
