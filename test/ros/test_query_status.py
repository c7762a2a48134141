"""The node over real DDS: a ~/query_shape reply says what it is (#35), in ``plan.header.frame_id``
(dlo_ros/node/query_reply.py, msg_docs/node.md): a verified shape carries the node's frame and its
poses; an impossible target the ``#no_equilibrium`` suffix and no poses; a bad request ``#invalid``.
DloClient.query_shape decodes each into its status; DloClient.query returns only verified shapes."""
from __future__ import annotations

import numpy as np
import pytest

from support.node import clean_node, node_args

Q = (0.0, 0.0, 0.0, 1.0)
LEFT = ((0.0, 0.0, 0.4), Q)


@pytest.fixture
def node(tmp_path):
    with clean_node(*node_args(), log_path=tmp_path / "node.log") as proc_client:
        yield proc_client


def test_query_replies_carry_their_status_and_the_client_decodes_it(node):
    _, cl = node
    near = ((0.58, 0.02, 0.39), Q)  # 2 cm from the held right grip: an ordinary, reachable target
    verified = cl.query_shape(LEFT, near, timeout=120.0)
    assert verified.status == "verified" and verified.verified, verified.status
    assert verified.frame_id == cl.frame_id
    assert len(verified.points) > 2 and np.allclose(verified.points[-1], near[0], atol=1e-6)
    np.testing.assert_allclose(cl.query(LEFT, near, timeout=120.0)[0], verified.points, atol=1e-9)

    none = cl.query_shape(LEFT, ((3.0, 0.0, 0.4), Q), timeout=120.0)  # 3 m apart: the string is 1 m
    assert none.status == "no_equilibrium" and not none.verified
    assert none.frame_id == cl.frame_id and len(none.points) == 0
    assert len(cl.query(LEFT, ((3.0, 0.0, 0.4), Q), timeout=120.0)[0]) == 0

    bad = cl.query_shape(LEFT, ((0.5, 0.0, 0.4), (0.0, 0.0, 0.0, 0.0)), timeout=120.0)  # zero quaternion
    assert bad.status == "invalid" and len(bad.points) == 0
