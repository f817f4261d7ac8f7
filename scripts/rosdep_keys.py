#!/usr/bin/env python3
"""
Write test/data/rosdep_jazzy.txt from a checkout of github.com/ros/rosdistro.

    python3 scripts/rosdep_keys.py PATH_TO_ROSDISTRO_CHECKOUT

The file lists the rosdep keys of rosdep/base.yaml and rosdep/python.yaml that have an
ubuntu or a pip rule (``key NAME``) and the packages released into ROS 2 Jazzy
(jazzy/distribution.yaml, ``package NAME``), with the rosdistro commit in its header.
test/test_rosdep_keys.py checks every package.xml dependency against it, so that
``rosdep install --from-paths src`` resolves on a Jazzy machine.
"""

import os
import subprocess
import sys

import yaml

OUTPUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'test', 'data',
                      'rosdep_jazzy.txt')


def main(args=None):
    """Read the rosdistro checkout named on the command line; write the key list."""
    args = sys.argv[1:] if args is None else args
    if len(args) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    checkout = args[0]

    def load(path):
        with open(os.path.join(checkout, path)) as stream:
            return yaml.safe_load(stream)
    commit = subprocess.check_output(['git', '-C', checkout, 'rev-parse', 'HEAD'],
                                     text=True).strip()
    keys = {key for path in ('rosdep/base.yaml', 'rosdep/python.yaml')
            for key, rules in load(path).items()
            if isinstance(rules, dict) and ('ubuntu' in rules or 'pip' in rules)}
    packages = set()
    for name, repository in load('jazzy/distribution.yaml')['repositories'].items():
        release = repository.get('release')
        if release:
            packages.update(release.get('packages', [name]))
    with open(OUTPUT, 'w') as out:
        out.write('# rosdep keys (rosdep/base.yaml, rosdep/python.yaml: those with an ubuntu or '
                  'a pip rule)\n# and ROS 2 Jazzy released packages (jazzy/distribution.yaml) '
                  f'of github.com/ros/rosdistro\n# at {commit}; regenerate with '
                  'scripts/rosdep_keys.py ROSDISTRO_CHECKOUT.\n')
        out.writelines(f'key {key}\n' for key in sorted(keys))
        out.writelines(f'package {name}\n' for name in sorted(packages))
    print(f'{len(keys)} keys, {len(packages)} packages -> {OUTPUT}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
