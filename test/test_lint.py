"""The system tests follow the packages' style rules (ament_flake8 and ament_pep257)."""

import os

import ament_flake8
from ament_flake8.main import main_with_errors
from ament_pep257.main import main as pep257_main

HERE = os.path.dirname(os.path.abspath(__file__))


def test_flake8(tmp_path):
    # in-process with one job, like the packages' lint tests (no fork after DDS started)
    ament_config = os.path.join(
        os.path.dirname(ament_flake8.__file__), 'configuration', 'ament_flake8.ini')
    config = tmp_path / 'flake8.ini'
    with open(ament_config) as rules:
        config.write_text(rules.read().rstrip('\n') + '\njobs = 1\n')
    rc, errors = main_with_errors(argv=['--config', str(config), HERE])
    assert rc == 0, f'{len(errors)} code style errors:\n' + '\n'.join(errors)


def test_pep257():
    assert pep257_main(argv=[HERE]) == 0, 'docstring style errors (see the output above)'
