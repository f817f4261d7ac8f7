# Copyright 2017 Open Source Robotics Foundation, Inc.
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

import os
import subprocess
import sys

import pytest

PACKAGE_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    # In a fresh process: flake8 forks its workers, and forking this pytest process after
    # the node tests have started DDS and emulator threads can crash the workers (seen:
    # a segfault in the child's garbage collector) and leave flake8 waiting forever.
    result = subprocess.run(
        [sys.executable, '-c',
         'import sys; from ament_flake8.main import main; sys.exit(main(argv=[]))'],
        cwd=PACKAGE_ROOT, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, \
        'Found code style errors / warnings:\n' + result.stdout + result.stderr
