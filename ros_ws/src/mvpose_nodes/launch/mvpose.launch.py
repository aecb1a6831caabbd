"""The mvpose graph for a system ROS 2 Jazzy install: `ros2 launch mvpose_nodes mvpose.launch.py`.

One camera_features node per camera, in the camera's namespace (/cam<K>), and one
skeleton_fitter. `cameras:=[2,4,7]` picks another subset of the rig. The same graph without
ros2launch: ./mvpose launch ros_ws/src/mvpose_nodes/config/mvpose.launch.yaml
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def graph(context):
    cameras = [int(k) for k in LaunchConfiguration('cameras').perform(context).strip('[] ').split(',')]
    parameters = os.path.join(get_package_share_directory('mvpose_nodes'), 'config', 'camera_features.yaml')
    features = [Node(package='mvpose_nodes', executable='camera_features', name='camera_features',
                     namespace=f'cam{k}', parameters=[parameters], output='screen') for k in cameras]
    fitter = Node(package='mvpose_nodes', executable='skeleton_fitter', name='skeleton_fitter',
                  parameters=[{'cameras': cameras}], output='screen')
    return [*features, fitter]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument('cameras', default_value='[3,5,7]', description='i3DPost camera numbers to use'),
        OpaqueFunction(function=graph),
    ])
