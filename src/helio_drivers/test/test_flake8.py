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

import ament_flake8
from ament_flake8.main import main_with_errors
import pytest


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8(tmp_path):
    # ament_flake8's own rules, checked in this process: flake8's default worker pool forks,
    # and forking after the node tests have started Fast DDS threads can crash or hang.
    ament_config = os.path.join(
        os.path.dirname(ament_flake8.__file__), 'configuration', 'ament_flake8.ini')
    config = tmp_path / 'flake8.ini'
    with open(ament_config) as rules:
        config.write_text(rules.read().rstrip('\n') + '\njobs = 1\n')
    rc, errors = main_with_errors(argv=['--config', str(config)])
    assert rc == 0, \
        'Found %d code style errors / warnings:\n' % len(errors) + \
        '\n'.join(errors)
