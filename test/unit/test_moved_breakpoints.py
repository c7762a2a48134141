"""``adapt/moved_breakpoints.moved_onto``: the nearer movable end of an element onto a contact inside it."""

from __future__ import annotations

from dlo_ros.solver.adapt.moved_breakpoints import moved_onto
from dlo_ros.solver.build.mesh import MeshSpec

L = 1.0


def test_the_nearer_end_moves_and_the_counts_stay():
    spec = MeshSpec((0.3, 0.6), (8, 10, 8))
    assert moved_onto(spec, L, (0.52,)) == MeshSpec((0.3, 0.52), (8, 10, 8))
    assert moved_onto(spec, L, (0.35,)) == MeshSpec((0.35, 0.6), (8, 10, 8))
    # two contacts in one element: each takes one end
    assert moved_onto(spec, L, (0.34, 0.55)) == MeshSpec((0.34, 0.55), (8, 10, 8))


def test_scene_breakpoints_and_the_ends_never_move():
    spec = MeshSpec((0.3, 0.6), (8, 10, 8))
    # 0.6 is the scene's (a grip, a load): the farther end 0.3 moves instead
    assert moved_onto(spec, L, (0.55,), fixed=(0.6,)) == MeshSpec((0.55, 0.6), (8, 10, 8))
    # in the first element only 0.3 may move; with it fixed, no end may: None (split instead)
    assert moved_onto(spec, L, (0.1,), fixed=(0.3,)) is None
    # one element: no interior breakpoint at all
    assert moved_onto(MeshSpec((), (12,)), L, (0.4,)) is None


def test_a_move_keeps_every_element_at_least_min_size():
    spec = MeshSpec((0.3, 0.6), (8, 10, 8))
    # moving 0.3 onto 0.302 leaves [0.302, 0.6] fine, and the nearer end is 0.3
    assert moved_onto(spec, L, (0.302,), min_size=1e-3) == MeshSpec((0.302, 0.6), (8, 10, 8))
    # 0.6 is the nearer end of [0.3, 0.6]: it moves, both elements stay long
    assert moved_onto(spec, L, (0.5995,), min_size=1e-3) == MeshSpec((0.3, 0.5995), (8, 10, 8))
    # a contact 0.5 mm from the string's end in the last element: 0.6 would leave [0.9995, 1]
    assert moved_onto(spec, L, (0.9995,), min_size=1e-3) is None


def test_nothing_to_move():
    spec = MeshSpec((0.3, 0.6), (8, 10, 8))
    assert moved_onto(spec, L, ()) is None
    assert moved_onto(spec, L, (0.3,)) is None  # on a breakpoint already
