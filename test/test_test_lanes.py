"""
The package tests' lanes (scripts/test_lanes.py): every package in one lane, and balanced.

The greedy rule is checked against the best split found by trying every one (an
independent method), within its known bound (4/3 of the best, Graham 1969).
"""

import importlib.util
import itertools
import os
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = os.path.join(REPO, 'scripts', 'test_lanes.py')
spec = importlib.util.spec_from_file_location('test_lanes', SCRIPT)
test_lanes = importlib.util.module_from_spec(spec)
spec.loader.exec_module(test_lanes)
WEIGHTS = test_lanes.TEST_SECONDS


def longest_lane(lanes):
    return max(sum(WEIGHTS.get(package, 1) for package in lane) for lane in lanes)


def best_longest_lane(packages, count):
    """Return the longest lane of the best split, by trying every assignment."""
    best = float('inf')
    for assignment in itertools.product(range(count), repeat=len(packages)):
        loads = [0] * count
        for package, lane in zip(packages, assignment):
            loads[lane] += WEIGHTS.get(package, 1)
        best = min(best, max(loads))
    return best


@pytest.mark.parametrize('count', [1, 2, 3])
def test_every_package_lands_in_exactly_one_lane_near_the_best_split(count):
    packages = sorted(name for name in WEIGHTS if name.startswith('helio_')) + ['a_new']
    lanes = test_lanes.lanes_of(packages, count)
    dealt = [package for lane in lanes for package in lane]
    assert sorted(dealt) == sorted(packages)
    assert len(lanes) == min(count, len(packages))
    assert longest_lane(lanes) <= 4 / 3 * best_longest_lane(packages, count)


def test_test_files_are_weighed_by_their_module_name():
    assert test_lanes.weight('/any/where/test/test_painter.py') == WEIGHTS['test_painter']
    assert test_lanes.weight('test_never_measured.py') == 1
    lanes = test_lanes.lanes_of(['test/test_painter.py', 'test/test_painter_safety.py',
                                 'test/test_doctor.py'], 2)
    assert sorted(map(len, lanes)) == [1, 2]


def test_the_command_prints_one_lane_per_line_and_refuses_a_bad_count():
    out = subprocess.run([sys.executable, SCRIPT, '2', 'helio_optics', 'helio_drivers'],
                         capture_output=True, text=True, check=True).stdout
    assert sorted(line.split() for line in out.splitlines()) == [['helio_drivers'],
                                                                 ['helio_optics']]
    refused = subprocess.run([sys.executable, SCRIPT, 'two', 'helio_optics'],
                             capture_output=True, text=True)
    assert refused.returncode != 0 and 'usage' in refused.stderr
