"""
The workspace's layering holds: no package imports from a package above it.

msgs < optics < (perception, drivers) < control. ``helio_optics`` holds the node kit and the
camera model every package shares; perception and simulation/drivers stand side by side and
share nothing but what lies below them; ``helio_control`` may use all of them.
"""

import ast
import os

import pytest

SRC = os.path.join(os.path.dirname(__file__), '..', 'src')
# what each Python package may import, besides itself
ALLOWED = {
    'helio_optics': {'helio_msgs'},
    'helio_perception': {'helio_msgs', 'helio_optics'},
    'helio_drivers': {'helio_msgs', 'helio_optics'},
    'helio_control': {'helio_msgs', 'helio_optics', 'helio_perception', 'helio_drivers'},
}
HELIO_PACKAGES = {'helio_msgs', *ALLOWED}


def imported_helio_packages(path):
    """Return {(package, line)} of every helio package imported by the file at `path`."""
    with open(path, encoding='utf-8') as stream:
        tree = ast.parse(stream.read(), path)
    found = set()
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        for name in names:
            top = name.split('.')[0]
            if top in HELIO_PACKAGES:
                found.add((top, node.lineno))
    return found


def python_files(package):
    """Yield the package's module and test files."""
    for root, _, files in os.walk(os.path.join(SRC, package)):
        for name in files:
            if name.endswith('.py'):
                yield os.path.join(root, name)


@pytest.mark.parametrize('package', sorted(ALLOWED))
def test_no_package_imports_from_a_package_above_it(package):
    wrong = []
    for path in python_files(package):
        for imported, line in imported_helio_packages(path):
            if imported != package and imported not in ALLOWED[package]:
                wrong.append(f'{os.path.relpath(path, SRC)}:{line} imports {imported}')
    assert not wrong, '\n'.join(wrong)


def test_the_check_sees_an_upward_import(tmp_path):
    # the check itself can fail: a drivers module importing perception is caught
    module = tmp_path / 'bad.py'
    module.write_text('from helio_perception.thermal import ThermalAnalyzer\nimport numpy\n')
    assert imported_helio_packages(str(module)) == {('helio_perception', 1)}


def test_every_package_depends_in_its_package_xml_on_what_it_imports():
    for package, allowed in ALLOWED.items():
        with open(os.path.join(SRC, package, 'package.xml'), encoding='utf-8') as stream:
            manifest = stream.read()
        used = {imported for path in python_files(package)
                if os.sep + 'test' + os.sep not in path
                for imported, _ in imported_helio_packages(path)} - {package}
        for dependency in used:
            assert f'<exec_depend>{dependency}</exec_depend>' in manifest, \
                f'{package}/package.xml lacks <exec_depend>{dependency}</exec_depend>'


def test_no_two_modules_share_a_name_across_packages():
    # a name like node_support.py in two packages hides two different things behind one word
    seen = {}
    shared = {'__init__.py', 'bench.py', 'setup.py', 'conftest.py', 'test_flake8.py',
              'test_pep257.py'}
    for package in ALLOWED:
        for path in python_files(package):
            name = os.path.basename(path)
            if name in shared:
                continue
            seen.setdefault(name, []).append(os.path.relpath(path, SRC))
    twice = {name: paths for name, paths in seen.items() if len(paths) > 1}
    assert not twice, twice
