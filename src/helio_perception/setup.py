from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'helio_perception'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        (os.path.join('share', package_name, 'config'),
         glob('config/*.yaml') + glob('config/*.xml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='helio developers',
    maintainer_email='helio@example.com',
    description='Light-spot detection on the ground plane and thermal pyrolysis monitoring.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'spot_detector = helio_perception.spot_detector_node:main',
            'thermal_monitor = helio_perception.thermal_monitor_node:main',
        ],
    },
)
