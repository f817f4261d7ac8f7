from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'helio_drivers'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        (os.path.join('share', package_name, 'config'), glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='helio developers',
    maintainer_email='helio@example.com',
    description='Dobot and servo drivers, device emulators and the simulated world.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'dobot_driver = helio_drivers.dobot_driver_node:main',
            'servo_driver = helio_drivers.servo_driver_node:main',
            'sim_world = helio_drivers.sim.world_node:main',
        ],
    },
)
