"""ament_python package setup: scripts go to lib/endeff_ros so that `ros2 run` finds them."""

from glob import glob

from setuptools import find_packages, setup

package_name = 'endeff_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(include=[package_name, package_name + '.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config',
         glob('config/*.yaml') + glob('config/*.xml') + glob('config/*.rviz')),
        ('share/' + package_name + '/launch', glob('launch/*.py')),
    ],
    # The committed motion-capture clips (and their licence notices), the real frames and the
    # confidence and kind models.
    package_data={'endeff_ros.synth.mocap': ['data/*/*'],
                  'endeff_ros.realdata': ['data/*/*'],
                  'endeff_ros.core': ['confidence_model.json', 'kind_model.json']},
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='endeff_ros developers',
    maintainer_email='dev@endeff.invalid',
    description='Time-consistent end-effector estimation from RGB-D data.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'endeff_node = endeff_ros.ros.node:main',
            'endeff = endeff_ros.cli:main',
        ],
    },
)
