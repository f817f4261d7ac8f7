"""
Every package.xml dependency resolves with rosdep on ROS 2 Jazzy (issue 30, item 5).

``rosdep install --from-paths src --ignore-src`` failed: python3-pysolar,
python3-threadpoolctl, python3-fast-tsp-pip and python3-mcap-pip are no rosdep keys. The
truth is rosdistro's own files, kept as data (test/data/rosdep_jazzy.txt, written by
scripts/rosdep_keys.py from a rosdistro checkout, its commit in the header): each
dependency is a package of this workspace, a package released into Jazzy, or a rosdep key
with an ubuntu or pip rule. What has no key is pip-only, as the model ROS packages do it:
installed from requirements/project.txt, named in a comment of the package.xml that needs
it.
"""

import glob
import os
import re
import xml.etree.ElementTree as ElementTree

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(REPO, 'test', 'data', 'rosdep_jazzy.txt')
DEPENDENCY_TAGS = ('depend', 'build_depend', 'build_export_depend', 'buildtool_depend',
                   'exec_depend', 'test_depend', 'doc_depend')
# pip distributions without a rosdep key, and the package.xml files whose code imports them
PIP_ONLY = {'pysolar': ('helio_optics',), 'threadpoolctl': ('helio_optics', 'helio_control'),
            'fast-tsp': ('helio_control',), 'mcap': ('helio_control',),
            'mcap-ros2-support': ('helio_control',)}


def rosdistro():
    """Return (rosdep keys, Jazzy packages) of the data file."""
    keys, packages = set(), set()
    with open(DATA) as stream:
        for line in stream:
            kind, _, name = line.strip().partition(' ')
            if kind == 'key':
                keys.add(name)
            elif kind == 'package':
                packages.add(name)
    return keys, packages


def manifests():
    """Return {package name: (path, [(tag, dependency)])} of the workspace's package.xml."""
    found = {}
    for path in sorted(glob.glob(os.path.join(REPO, 'src', '*', 'package.xml'))):
        root = ElementTree.parse(path).getroot()
        dependencies = [(element.tag, element.text.strip()) for element in root
                        if element.tag in DEPENDENCY_TAGS]
        found[root.findtext('name').strip()] = (path, dependencies)
    return found


def test_the_data_is_rosdistros():
    keys, packages = rosdistro()
    with open(DATA) as stream:
        header = stream.read(400)
    assert re.search(r'ros/rosdistro\n# at [0-9a-f]{40}', header)
    # a few known entries each way (rosdistro's own files say so)
    assert {'python3-numpy', 'python3-opencv', 'python3-serial'} <= keys
    assert {'rclpy', 'std_srvs', 'rosbag2', 'usb_cam'} <= packages
    assert 'python3-pysolar' not in keys and 'helio_msgs' not in packages


def test_every_dependency_resolves_with_rosdep_on_jazzy():
    keys, packages = rosdistro()
    workspace = manifests()
    unresolved = [f'{os.path.relpath(path, REPO)}: <{tag}>{name}'
                  for path, dependencies in workspace.values()
                  for tag, name in dependencies
                  if name not in keys and name not in packages and name not in workspace]
    assert not unresolved, ('not a rosdep key nor a Jazzy package (pip-only? then list it in '
                            'requirements/project.txt and in a package.xml comment): '
                            f'{unresolved}')


@pytest.mark.parametrize('distribution', sorted(PIP_ONLY))
def test_each_pip_only_dependency_is_installed_from_requirements_and_said(distribution):
    keys, _ = rosdistro()
    assert f'python3-{distribution}' not in keys     # else it belongs in package.xml
    with open(os.path.join(REPO, 'requirements', 'project.txt')) as stream:
        required = {line.split('#')[0].strip().lower() for line in stream}
    assert distribution in required
    workspace = manifests()
    for package in PIP_ONLY[distribution]:
        with open(workspace[package][0]) as stream:
            assert distribution in stream.read(), f'{package}/package.xml does not name it'
