"""Launch the managed dlo node with nav2's lifecycle manager (`ros2 launch dlo_ros dlo_managed.launch.py`).

Arguments:
  params_file   ROS parameters YAML (default: <share>/dlo_ros/config/dlo_node.yaml)
  scene         scene name or path; empty (default): the params file's `scene`
  namespace     namespace of both nodes (default: none)
  node_name     the dlo node's name (default: dlo)
  autostart     configure and activate the node at once (default: true)
  log_level     debug, info, warn, error (default: info)

The dlo node runs with `managed: true` (msg_docs/node.md, "Managed node"); nav2_lifecycle_manager
(apt: ros-jazzy-nav2-lifecycle-manager) drives its transitions.  The node creates no bond, so the
manager's bond_timeout is 0 (off).  launch, launch_ros and nav2 come with a ROS 2 installation;
without nav2, drive the node with any lifecycle client (`ros2 lifecycle set /dlo configure`).
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import LifecycleNode, Node
from launch_ros.substitutions import FindPackageShare


def _nodes(context, *args, **kwargs):
    params = [LaunchConfiguration('params_file').perform(context), {'managed': True}]
    scene = LaunchConfiguration('scene').perform(context)
    if scene:
        params.append({'scene': scene})
    name = LaunchConfiguration('node_name').perform(context)
    autostart = LaunchConfiguration('autostart').perform(context).lower() in ('true', '1', 'yes')
    return [
        LifecycleNode(
            package='dlo_ros',
            executable='dlo_node',
            name=name,
            namespace=LaunchConfiguration('namespace'),
            parameters=params,
            arguments=['--ros-args', '--log-level', LaunchConfiguration('log_level')],
            output='screen',
            emulate_tty=True,
            sigterm_timeout='10',
        ),
        Node(
            package='nav2_lifecycle_manager',
            executable='lifecycle_manager',
            name='lifecycle_manager_dlo',
            namespace=LaunchConfiguration('namespace'),
            parameters=[{'node_names': [name], 'autostart': autostart, 'bond_timeout': 0.0}],
            output='screen',
        ),
    ]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument(
            'params_file',
            default_value=PathJoinSubstitution([FindPackageShare('dlo_ros'), 'config', 'dlo_node.yaml']),
            description='ROS parameters YAML of the dlo node'),
        DeclareLaunchArgument('scene', default_value='', description='scene name or path (empty: from params_file)'),
        DeclareLaunchArgument('namespace', default_value='', description='namespace of both nodes'),
        DeclareLaunchArgument('node_name', default_value='dlo', description='the dlo node\'s name'),
        DeclareLaunchArgument('autostart', default_value='true', description='configure and activate at once'),
        DeclareLaunchArgument('log_level', default_value='info', description='logging level'),
        OpaqueFunction(function=_nodes),
    ])
