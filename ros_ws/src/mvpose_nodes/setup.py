from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'mvpose_nodes'

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
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/config', glob('config/*.yaml')),
        (f'share/{PACKAGE}/launch', glob('launch/*.py')),
        (f'share/{PACKAGE}/data', glob('data/*.npz')),
        (f'share/{PACKAGE}/data/cmu', glob('data/cmu/*')),
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
