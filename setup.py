"""ament_python build description for dlo_ros (colcon build / pip install)."""

from glob import glob

from setuptools import find_packages, setup

package_name = 'dlo_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'bench', 'bench.*']),
    # the compiled Newton drivers' C, read through importlib.resources (solver/native/build.py)
    package_data={'dlo_ros.solver': ['native/*.c', 'native/*.h']},
    data_files=[
        # Marker that makes the package visible to ament_index_python / `ros2 pkg`.
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        # glob() so that empty directories are fine.
        ('share/' + package_name + '/config', sorted(glob('config/*.yaml'))),
        ('share/' + package_name + '/config/scenes', sorted(glob('config/scenes/*.yaml'))),
        ('share/' + package_name + '/config/observations', sorted(glob('config/observations/*'))),  # dlo fit example
        ('share/' + package_name + '/config/plans', sorted(glob('config/plans/*.yaml'))),  # dlo dataset example
        ('share/' + package_name + '/launch', sorted(glob('launch/*.py'))),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='dlo_ros maintainers',
    maintainer_email='dlo_ros@example.com',
    description='Static shape prediction for deformable linear objects held by robot grippers.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'dlo = dlo_ros.console:dlo',
            'dlo_node = dlo_ros.console:dlo_node',
        ],
    },
)
