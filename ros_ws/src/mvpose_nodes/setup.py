import os
from glob import glob as all_entries

from setuptools import find_packages, setup

PACKAGE = 'mvpose_nodes'


def glob(pattern):
    """The files matching pattern. colcon --symlink-install builds from a tree of links to the sources and
    keeps the links of files since moved or deleted; those dangle, and installing one would fail."""
    return [path for path in all_entries(pattern) if os.path.isfile(path)]

# Every node and tool is a console script in lib/mvpose_nodes, where `ros2 run` finds it.
EXECUTABLES = {
    'camera_features': 'mvpose_nodes.nodes.camera_features:main',
    'skeleton_fitter': 'mvpose_nodes.nodes.skeleton_fitter:main',
    'marker_tracker': 'mvpose_nodes.nodes.marker_tracker:main',
    'marker_skeleton': 'mvpose_nodes.nodes.marker_skeleton:main',
    'bag': 'mvpose_nodes.tools.bag:main',
    'topic': 'mvpose_nodes.tools.topic:main',
    'launch': 'mvpose_nodes.tools.launch:main',
}

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    # The studio's motion-capture clips travel with its code (no ament index needed to find them).
    package_data={f'{PACKAGE}.studio': ['cmu/*', 'motions/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/config', glob('config/*.yaml') + glob('config/*.xml')),
        (f'share/{PACKAGE}/launch', glob('launch/*.launch.yaml')),  # for `ros2 launch mvpose_nodes FILE`
        (f'share/{PACKAGE}/data', glob('data/*.npz')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='mvpose maintainers',
    maintainer_email='maintainers@mvpose.dev',
    description='mvpose nodes and tools',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [f'{name} = {target}' for name, target in EXECUTABLES.items()],
    },
)
