"""Launch endeff_node in the camera's namespace with the packaged parameters and DDS profile.

    ros2 launch endeff_ros endeff.launch.py [namespace:=camera] [params_file:=...]
        [color_topic:=color/image_raw] [depth_topic:=depth/image_raw]
        [camera_info_topic:=depth/camera_info] [use_sim_time:=false]
        [fastdds_profile:=<share>/config/fastdds_shm.xml]
        [rviz:=false] [rviz_config:=<share>/config/endeff.rviz]

The parameter file's ``endeff_node: ros__parameters:`` block is read here and handed to the node
as a dictionary, so it applies whatever namespace the node runs in (a plain ``--params-file``
key ``endeff_node`` would only match the root namespace).

``rviz:=true`` starts RViz2 too, with ``config/endeff.rviz``: the depth image's cloud, the
end-effectors with their labels (``hand 7``) and the bands, under the ``/camera`` namespace
and in the frame ``camera_color_optical_frame`` (set RViz's Fixed Frame to your depth
image's frame_id if it differs; docs/output.md).
"""

from __future__ import annotations

import os

import yaml
from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction, SetEnvironmentVariable
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from launch import LaunchContext, LaunchDescription

PACKAGE = 'endeff_ros'
NODE_NAME = 'endeff_node'


def _node_parameters(path: str) -> dict:
    """The ``ros__parameters`` of ``endeff_node`` (or ``/**``) in a ROS 2 parameter file."""
    with open(path, encoding='utf-8') as fh:
        data = yaml.safe_load(fh) or {}
    for key, value in data.items():
        if key in ('/**', NODE_NAME) or str(key).endswith('/' + NODE_NAME):
            return dict(value.get('ros__parameters', {}))
    return {}


def _launch_node(context: LaunchContext) -> list:
    params_file = LaunchConfiguration('params_file').perform(context)
    parameters = [_node_parameters(params_file), {
        'use_sim_time': ParameterValue(LaunchConfiguration('use_sim_time'), value_type=bool)}]
    return [Node(
        package=PACKAGE, executable=NODE_NAME, name=NODE_NAME,
        namespace=LaunchConfiguration('namespace'), parameters=parameters,
        remappings=[('color/image_raw', LaunchConfiguration('color_topic')),
                    ('depth/image_raw', LaunchConfiguration('depth_topic')),
                    ('depth/camera_info', LaunchConfiguration('camera_info_topic'))],
        output='screen', emulate_tty=True)]


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory(PACKAGE)
    profile = os.path.join(share, 'config', 'fastdds_shm.xml')
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='camera',
                              description='Namespace of the camera driver topics.'),
        DeclareLaunchArgument('params_file',
                              default_value=os.path.join(share, 'config', 'endeff.yaml'),
                              description='ROS 2 parameter file for endeff_node.'),
        DeclareLaunchArgument('fastdds_profile', default_value=profile,
                              description='Fast DDS XML profile (shared-memory transport).'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='Use /clock (bag replay).'),
        DeclareLaunchArgument('color_topic', default_value='color/image_raw'),
        DeclareLaunchArgument('depth_topic', default_value='depth/image_raw'),
        DeclareLaunchArgument('camera_info_topic', default_value='depth/camera_info'),
        DeclareLaunchArgument('rviz', default_value='false',
                              description='Also start RViz2 showing the outputs.'),
        DeclareLaunchArgument('rviz_config',
                              default_value=os.path.join(share, 'config', 'endeff.rviz'),
                              description='RViz2 configuration for rviz:=true.'),
        SetEnvironmentVariable('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp'),
        SetEnvironmentVariable('FASTDDS_DEFAULT_PROFILES_FILE',
                               LaunchConfiguration('fastdds_profile')),
        SetEnvironmentVariable('FASTRTPS_DEFAULT_PROFILES_FILE',
                               LaunchConfiguration('fastdds_profile')),
        OpaqueFunction(function=_launch_node),
        Node(package='rviz2', executable='rviz2', name='rviz2', output='screen',
             arguments=['-d', LaunchConfiguration('rviz_config')],
             parameters=[{'use_sim_time': ParameterValue(LaunchConfiguration('use_sim_time'),
                                                         value_type=bool)}],
             condition=IfCondition(LaunchConfiguration('rviz'))),
    ])
