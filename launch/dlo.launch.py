"""Launch the dlo node (colcon workspaces: `ros2 launch dlo_ros dlo.launch.py [arg:=value ...]`).

Arguments:
  params_file   ROS parameters YAML (default: <share>/dlo_ros/config/dlo_node.yaml)
  scene         scene name or path; empty (default): the params file's `scene`
  namespace     node namespace (default: none)
  node_name     node name (default: dlo)
  log_level     debug, info, warn, error (default: info)

launch and launch_ros come with a ROS 2 installation (they are not on PyPI); the node itself also
runs without them: `python -m dlo_ros.node --params-file FILE`.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def _node(context, *args, **kwargs):
    params = [LaunchConfiguration('params_file').perform(context)]
    scene = LaunchConfiguration('scene').perform(context)
    if scene:
        params.append({'scene': scene})
    return [Node(
        package='dlo_ros',
        executable='dlo_node',
        name=LaunchConfiguration('node_name'),
        namespace=LaunchConfiguration('namespace'),
        parameters=params,
        arguments=['--ros-args', '--log-level', LaunchConfiguration('log_level')],
        output='screen',
        emulate_tty=True,
        # SIGINT first; the node stops its solver thread and exits cleanly within a few seconds.
        sigterm_timeout='10',
    )]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument(
            'params_file',
            default_value=PathJoinSubstitution([FindPackageShare('dlo_ros'), 'config', 'dlo_node.yaml']),
            description='ROS parameters YAML of the dlo node'),
        DeclareLaunchArgument('scene', default_value='', description='scene name or path (empty: from params_file)'),
        DeclareLaunchArgument('namespace', default_value='', description='node namespace'),
        DeclareLaunchArgument('node_name', default_value='dlo', description='node name'),
        DeclareLaunchArgument('log_level', default_value='info', description='logging level'),
        OpaqueFunction(function=_node),
    ])
