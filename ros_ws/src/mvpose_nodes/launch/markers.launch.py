"""Marker mode for a system ROS 2 Jazzy install: `ros2 launch mvpose_nodes markers.launch.py`.

One marker_tracker per camera, in the camera's namespace (/cam<K>), and one marker_skeleton fusing
them. `cameras:=[1,2,3,4,5,6,7,8]` uses more of the rig; `labelling:=initial_markers` takes the
calibration frame's labelling from /cam<K>/initial_markers instead of a synthetic bag's ground truth.
The same graph without ros2launch: ./mvpose launch ros_ws/src/mvpose_nodes/config/markers.launch.yaml
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def graph(context):
    cameras = [int(k) for k in LaunchConfiguration('cameras').perform(context).strip('[] ').split(',')]
    labelling = LaunchConfiguration('labelling').perform(context)
    parameters = os.path.join(get_package_share_directory('mvpose_nodes'), 'config', 'marker_tracker.yaml')
    trackers = [Node(package='mvpose_nodes', executable='marker_tracker', name='marker_tracker',
                     namespace=f'cam{k}', parameters=[parameters], remappings=[('initial_markers', labelling)],
                     output='screen') for k in cameras]
    fusion = Node(package='mvpose_nodes', executable='marker_skeleton', name='marker_skeleton',
                  parameters=[{'cameras': cameras}], output='screen')
    return [*trackers, fusion]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument('cameras', default_value='[3,5,7]', description='i3DPost camera numbers to use'),
        DeclareLaunchArgument('labelling', default_value='ground_truth/markers',
                              description="topic (in each camera's namespace) of the labelled calibration frame"),
        OpaqueFunction(function=graph),
    ])
