"""What auto compiles, and when.

``compile='blocking'`` under ``solver.model: auto``: the first solve runs compiled; a model a later
update switches to compiles in the background, never on the stream's thread.  A checked solve that
escalates (a cold solve refining its mesh) compiles only the model it answers with.

The node's ``compile:=blocking`` promises compiled derivatives before its first solve (msg_docs/node.md).
Every later switch of auto's model (to 3D, a refined mesh, an obstacle coming within reach) compiled
blocking too, on the stream's thread: on an empty cache a node held its centrelines back for over 10 s
at such a switch (bench/perf/node_latency.py --mode native: "no centreline for target 183").
"""

from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np

from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver import make_solver
from dlo_ros.solver.build.functions import NlpFunctions



def test_a_switch_after_the_first_solve_compiles_in_the_background(empty_cache):
    scene = load_scene("default_cable")
    auto = make_solver(scene.problem, replace(scene.options, model="auto"), compile="blocking", checks="sync")
    first = auto.solve()
    assert first.ok and auto.choice.planar
    assert auto.inner.kkt_compiled  # 'blocking': compiled before the first answer
    right = scene.problem.grip("right").pose
    # the right grip 5 cm out of the cable's plane: auto switches to its 3D model
    moved = auto.solve({"right": GripPose(right.position + np.array([0.0, 0.05, 0.0]), right.orientation)})
    assert moved.ok and not auto.choice.planar, moved.model.changed
    assert auto.inner.compile_mode == "background" and not auto.inner.kkt_compiled
    assert auto.inner.wait_for_compile(600.0)  # compiled beside the stream
    again = auto.solve({"right": GripPose(right.position + np.array([0.0, 0.06, 0.0]), right.orientation)})
    assert again.ok and again.derivatives == "compiled"


def test_a_checked_solves_escalations_compile_only_the_model_it_answers_with(empty_cache, monkeypatch):
    """The paper's Fig. 3 strip on its floor, cold: auto refines its mesh in several passes, each a
    model the solve streams on for one answer.  Each started a background compile (gcc on a model
    used once; code generation holding the GIL beside the solve: a sixth of the cold solve's time);
    now the first model (built before the solve) and the one the answer comes from compile."""
    started = []

    def compile_recorded(self, todo, mode, lock):  # a compile thread that runs no gcc
        started.append(self.nlp)
        thread = threading.Thread(target=lambda: None)
        thread.start()
        return thread

    monkeypatch.setattr(NlpFunctions, "_compile", compile_recorded)
    scene = load_scene("bench_fig3_floor")
    auto = make_solver(scene.problem, scene.options, compile="background", checks="sync")
    first = auto.inner.nlp
    result = auto.solve()
    assert result.ok and len(result.model.changed) >= 2, result.model.changed  # it escalated
    assert started == [first, auto.inner.nlp] and first is not auto.inner.nlp


def test_a_checked_solves_passes_do_not_look_for_libraries_keyed_by_their_own_meshes(empty_cache, monkeypatch):
    """'cached' (the CLI's mode): a pass's new model is keyed by its own mesh, whose libraries are almost
    never in the cache, and its key costs two evaluations of each of its functions.  Only the first model
    and the one the answer comes from look into the cache (the Fig. 3 strip: three passes between)."""
    from dlo_ros.solver.native import compiler as native_compiler

    keyed = []
    real = native_compiler._fingerprint
    monkeypatch.setattr(native_compiler, "_fingerprint", lambda fn, flags: keyed.append(fn.name()) or real(fn, flags))
    scene = load_scene("bench_fig3_floor")
    auto = make_solver(scene.problem, scene.options, compile="cached", checks="sync")
    per_model = len(keyed)
    assert per_model >= 3  # the first model looked for its derivatives' libraries
    result = auto.solve()
    assert result.ok and len(result.model.changed) >= 3, result.model.changed
    # and the model it answers with (its derivatives'; its outputs' function is built when it streams)
    assert per_model < len(keyed) <= 2 * per_model, keyed
