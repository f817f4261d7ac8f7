from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'helio_control'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        (os.path.join('share', package_name, 'config'), glob('config/*.yaml')),
        (os.path.join('share', package_name, 'launch'), glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='helio developers',
    maintainer_email='helio@example.com',
    description='Picture to ordered dots and the painting procedure (Algorithm 1).',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'lens_planner = helio_control.lens_planner_node:main',
            'painter = helio_control.painter_node:main',
            'helio = helio_control.cli:main',
            'recorder = helio_control.recorder:main',
            'replayer = helio_control.replay:main',
            'view_bridge = helio_control.view_bridge:main',
        ],
    },
)
