"""The node publishes the cable as capsules (#40) over real DDS: ~/capsules holds a chain of radius
string.radius + padding/2 that contains every published centreline point's tube, and it follows the
shape when the targets move."""
from __future__ import annotations


import numpy as np

from dlo_ros.node.client import running_node
from dlo_ros.scene import load_scene
from support.node import TEST_SCENE, node_args
from visualization_msgs.msg import Marker, MarkerArray


LEFT = ((0.0, 0.0, 0.4), (0.0, 0.0, 0.0, 1.0))
RIGHT = ((0.45, 0.1, 0.3), (0.0, 0.0, 0.0, 1.0))
PADDING = 0.02


def segments(msg: MarkerArray) -> tuple[np.ndarray, np.ndarray, float]:
    """The capsules' axes (start, end points) and radius, from the cylinders and spheres."""
    spheres = sorted((m for m in msg.markers if m.type == Marker.SPHERE), key=lambda m: m.id)
    joints = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z] for m in spheres])
    radius = spheres[0].scale.x / 2
    return joints[:-1], joints[1:], radius


def distance_to_chain(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Each point's distance to the nearest capsule axis."""
    ab = b - a
    t = np.clip(np.einsum("pkj,kj->pk", points[:, None, :] - a[None], ab) / np.einsum("kj,kj->k", ab, ab),
                0.0, 1.0)
    nearest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(points[:, None, :] - nearest, axis=2).min(axis=1)


def test_the_capsules_contain_the_published_cable(tmp_path):
    args = node_args(f"planning_scene.padding:={PADDING}", "planning_scene.rate:=20.0")
    with running_node(*args, log_path=tmp_path / "node.log") as (proc, client):
        got = client.collect(MarkerArray, "capsules")
        assert client.wait_for(lambda: got, 10.0), proc.output()
        n = client.path_count
        client.publish_targets([LEFT, RIGHT])
        assert client.wait_for(lambda: client.path_count > n, 30.0)
        path = client.latest_path()

        def follows():  # the newest chain ends where the moved cable ends
            return got and np.allclose(segments(got[-1])[1][-1], path.points[-1], atol=1e-9) and got[-1]

        msg = client.wait_for(follows, 10.0)
        assert msg
        a, b, radius = segments(msg)
        assert msg.markers[0].action == Marker.DELETEALL
        assert all(m.header.frame_id == "world" for m in msg.markers[1:])
        assert 1 <= len(a) < len(path.points)
        # R = r + padding / 2; every published point within padding / 2 of an axis, so its tube of
        # radius r lies inside the chain
        assert abs(radius - (load_scene(TEST_SCENE).problem.string.radius + PADDING / 2)) < 1e-12
        assert distance_to_chain(path.points, a, b).max() <= PADDING / 2 + 1e-9
    assert proc.returncode == 0, proc.output()
