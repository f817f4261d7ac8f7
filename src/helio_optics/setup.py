from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'helio_optics'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        (os.path.join('share', package_name, 'config'), glob('config/*.yaml')),
        # The workspace's deployment data (top-level config/: rig, lens, site, DDS profile).
        (os.path.join('share', package_name, 'config'),
         sorted(glob('../../config/*.yaml') + glob('../../config/*.xml'))),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='helio developers',
    maintainer_email='helio@example.com',
    description='Lens ray tracing, spot model, sun estimation, ephemeris and kinematics.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'sun_estimator = helio_optics.sun_estimator_node:main',
        ],
    },
)
