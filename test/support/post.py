"""The heavy strip on a post (test/reference/post_contact.py solves it by shooting).

A string of L = 1 m clamped level at both ends 0.6 m apart at HEIGHT, hanging onto a round post (a
capsule across the x–z plane) below the chord.  Used by the contact and error-estimate tests.
"""

from __future__ import annotations

from reference import post_contact

from dlo_ros.scene import scene_from_dict

LEVEL = [0.0, 0.0, 0.0, 1.0]
BEND, WEIGHT, RADIUS = 0.02, 0.5, 0.005
POST, POST_RADIUS, HEIGHT = (0.22, 0.2), 0.03, 0.5


def post_scene(solver: dict):
    """Return the scene (``dlo_ros.scene.Scene``) with the ``solver`` section given."""
    post = {
        "type": "capsule",
        "name": "post",
        "radius": POST_RADIUS,
        "a": [POST[0], -0.3, POST[1]],
        "b": [POST[0], 0.3, POST[1]],
    }
    grips = [
        {"name": n, "s": s, "mode": "clamp", "position": [x, 0, HEIGHT], "orientation": LEVEL}
        for n, s, x in (("left", 0.0, 0.0), ("right", 1.0, 0.6))
    ]
    return scene_from_dict(
        {
            "name": "post",
            "frame_id": "world",
            "grips": grips,
            "obstacles": [post],
            "string": {
                "length": 1.0,
                "bend_stiffness": BEND,
                "twist_stiffness": 0.015,
                "weight_per_length": WEIGHT,
                "radius": RADIUS,
            },
            "gravity": {"direction": [0, 0, -1]},
            "solver": solver,
        }
    )


def shooting_reference(guess) -> post_contact.PostContact:
    """Return the shooting solution of this scene in the x–z plane from ``guess``.

    ``guess``: (n_x(0), n_z(0), m(0), s*, P), see ``test/reference/post_contact.py``.
    """
    return post_contact.solve(
        1.0,
        BEND,
        WEIGHT,
        [0.0, HEIGHT],
        0.0,
        [0.6, HEIGHT],
        0.0,
        POST,
        POST_RADIUS,
        RADIUS,
        guess,
    )
