"""The CasADi functions a solve evaluates: interpreted first, compiled C when ready.

The CasADi functions a solve evaluates, interpreted at first and swapped for compiled C when it
is ready.

One ``NlpFunctions`` per ``StringNLP``:

* ``kkt(z, p, λ)`` → [∇f, g, ∂g/∂z, ∇²L, energies] over every row (``StringNLP.kkt_fn``);
* ``kkt_free(z, p, λ_free)`` → [K, r, ∇f, energies], the Newton matrix K = [∇²L Jᵀ; J 0] and
  residual
  r = [∇f + Jᵀλ; g] of the rows other than the obstacle rows (``kkt_free_fn``);
* ``newton_step(u, p, K, r)`` → the first ``NEWTON_STEPS`` Newton steps in one call
  (``newton_fn``);
* ``newton_native``: once the contact-free function is compiled, the whole Newton loop as one
  compiled
  call (``native.newton.NativeNewton``; None until then);
* ``newton_active``: once the full KKT function is compiled, Newton's steps with a fixed active set
  as
  one compiled call (``native.newton.ActiveNewton``, in the KKT function's own library; None until
  then);
* ``saddle_escape``: with ``newton_active``, the shifted Newton steps that leave a saddle as one
  compiled call (``native.saddle.NativeSaddle``, the same library; None until then);
* ``obstacle_g(z, p)`` → the obstacle rows' values (None without obstacles);
* ``g(z, p)`` → every row's value, ``StringNLP.g_fn`` interpreted through its buffer (the same
  numbers as calling it, without the conversions to and from DM);
* ``outputs(z, p, λ, prof)``: a solution's published outputs in one call (``output_function.py``;
  None
  for the models it does not cover, whose outputs numpy evaluates), compiled last.

The KKT functions are compiled split (``StringNLP.kkt_free_split_fn``, ``kkt_split_fn``: without
the Hessian's per-node part Eᵀ W, which ``native.newton.WithNodePart`` adds by BLAS, as the
compiled loops do).

Compile modes: 'background' (solve at once with interpreted functions, compile them to C in a
background thread and swap each in when it is ready; libraries are cached per machine), 'blocking'
(compile or load now), 'cached' (load a library compiled earlier, never compile), 'on_query' (as
'cached' until the solver answers a query, ``solve(commit=False)``, while the cache lacks some of
its libraries: then it compiles those in the background at the process's own priority — a query
worker's model, ``parallel/batch.py``) and 'off'.  'cached' and 'on_query' look into the cache
again at most every CACHE_RECHECK_S for libraries another solver or process has built since.  One
library is built at a time per cache directory (``native.compiler.library_lock``): a process that
misses one another process is building waits for it and loads it.  $DLO_NO_COMPILE forces 'off'.
A swap happens under the solver's lock, so a solve never sees one midway.
"""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import casadi as ca
import numpy as np

from ..native import newton as native_newton
from ..native import saddle as native_saddle
from .assembled_contact import sparse
from .compiled import (
    FLAGS,
    DeferredFunction,
    InterpretedFunction,
    NativeFunction,
    compiled,
    compiler,
    library_path,
    load_native,
)
from .newton_function import newton_function
from .nlp import StringNLP
from .output_function import OutputFunction

COMPILE_MODES = ("background", "blocking", "cached", "on_query", "off")
#: the modes that wait for a library in the cache rather than build it at the start
WAITING_MODES = ("cached", "on_query")
#: ('cached', 'on_query') the least time [s] between two looks into the cache for libraries that
#: another solver or process has compiled since (e.g. a node's query model, for its query workers)
CACHE_RECHECK_S = 1.0


def check_compile_mode(mode: str) -> None:
    if mode not in COMPILE_MODES:
        raise ValueError(f"compile: must be one of {COMPILE_MODES}, got {mode!r}")


class NlpFunctions:
    """The evaluators of one NLP's functions (see the module docstring)."""

    def __init__(self, nlp: StringNLP, lazy_outputs: bool = False):
        """Wrap ``nlp``'s functions, interpreted until a compile swaps them.

        ``lazy_outputs``: build the outputs' function at the second solve (:meth:`solved`) or a
        compile, not now: a model solved once (a check's shadow, a moved mesh) answers through
        numpy, which costs less than building the function.
        """
        self.nlp = nlp
        self.kkt = InterpretedFunction(nlp.kkt_fn)
        # the contact-free ones on first use (``StringNLP.kkt_free_fn``), or ``prepare_newton``
        self.kkt_free: InterpretedFunction | DeferredFunction | native_newton.WithNodePart = (
            DeferredFunction(lambda: InterpretedFunction(nlp.kkt_free_fn))
        )
        self.newton_step: InterpretedFunction | DeferredFunction = DeferredFunction(
            lambda: InterpretedFunction(nlp.newton_fn)
        )
        self.obstacle_g = (
            InterpretedFunction(nlp.obstacle_g_fn) if nlp.obstacle_g_fn is not None else None
        )
        self.g = InterpretedFunction(nlp.g_fn)
        self.newton_native = None
        self.newton_active: native_newton.ActiveNewton | None = None
        self.saddle_escape: native_saddle.NativeSaddle | None = None
        #: the outputs' function and its structure (grid, profiles), None where numpy builds the
        #: outputs (a model it does not cover, or one not built yet: ``lazy_outputs``)
        self.output_function: OutputFunction | None = None
        self.outputs: InterpretedFunction | NativeFunction | None = None
        self.compiled = False  # every derivative function runs compiled C
        self.outputs_compiled = False  # the outputs' function runs compiled C
        self.compile_time_s = 0.0  # wall time of the compile that finished them [s]
        self.retired = False  # the solver was rebuilt: a running compile stops at its next swap
        #: ('cached', 'on_query') (name, function, library path) of each library not in the cache
        #: at the start
        self.waiting: list[tuple[str, ca.Function, Path]] = []
        self._cache_checked = time.monotonic()  # the last look into the cache for them
        self._solves = 0  # :meth:`solved`'s count
        if not lazy_outputs:
            self.build_outputs()

    def solved(self, mode: str) -> None:
        """Count a solve; at the second, build the outputs' function (``build_outputs``)."""
        if self._solves < 2:  # (every update calls this: one comparison after the second)
            self._solves += 1
            if self._solves == 2:
                self.build_outputs(mode)

    def prepare_newton(self) -> None:
        """Build the contact-free Newton functions now if they are still to be built on first use.

        For a model a stream may switch to, built on the worker: its first contact-free update
        then builds nothing on the stream's thread.  Not the steps around a compiled library,
        which serve only while its compiled loop is missing (``_install``).
        """
        if isinstance(self.kkt_free, DeferredFunction):
            self.kkt_free.built()
        if self.newton_native is None and isinstance(self.newton_step, DeferredFunction):
            self.newton_step.built()

    def build_outputs(self, mode: str = "off") -> None:
        """Build the outputs' function (interpreted) if it covers this model and is not built.

        ``mode``: the solver's compile mode; in 'cached' and 'on_query' the cache is looked into
        for its library (swapped in if there, else waited for as the other libraries missing at
        the start are).  The compiling modes build it before they compile (``start_compile``).
        """
        if self.output_function is not None or not OutputFunction.applies(self.nlp):
            return
        nlp = self.nlp
        plan = OutputFunction(
            nlp, nlp.problem, np.linspace(0.0, nlp.length, nlp.options.output_points)
        )
        self.output_function, self.outputs = plan, InterpretedFunction(plan.function)
        compiling = compiler() is not None and not os.environ.get("DLO_NO_COMPILE")
        if mode in WAITING_MODES and compiling:
            lib = library_path(plan.function)
            if not self._load("outputs", plan.function, lib):
                self.waiting.append(("outputs", plan.function, lib))

    def retire(self) -> None:
        """Mark these functions unused: a background compile stops before its next swap.

        The solver no longer uses these functions: a background compile stops before its next
        swap.
        """
        self.retired = True

    def start_compile(self, mode: str, lock: threading.Lock) -> threading.Thread | None:
        """Load the libraries compiled earlier and compile the others as ``mode`` says.

        Load the libraries compiled earlier and compile the others as ``mode`` says; the
        background thread if one was started.  ``lock``: the solver's lock, held for every swap.
        """
        if os.environ.get("DLO_NO_COMPILE"):
            mode = "off"
        if mode == "off" or compiler() is None:
            return None
        if mode not in WAITING_MODES:  # a model that compiles streams: its outputs too
            self.build_outputs()
        nlp = self.nlp
        # the contact-free function first: it is the one a stream uses while nothing touches
        todo = []
        outputs_fn = self.output_function.function if self.output_function is not None else None
        # the KKT functions compiled are the split ones (K without its per-node Hessian part, which
        # native_newton adds with BLAS), whose libraries the Newton loops share
        for name, fn in (
            ("kkt_free", nlp.kkt_free_split_fn),
            ("obstacle_g", nlp.obstacle_g_fn),
            ("kkt", nlp.kkt_split_fn),
            ("outputs", outputs_fn),
        ):
            if fn is None:
                continue
            # the full KKT function's library also holds its active-set Newton loop
            lib = native_newton.active_library_path(fn) if name == "kkt" else library_path(fn)
            if not self._load(name, fn, lib):  # not compiled on an earlier start
                todo.append((name, fn, lib))
        # the outputs' function is not a derivative: ``compiled`` says whether the derivatives are
        self.compiled = all(name == "outputs" for name, _, _ in todo)
        if mode in WAITING_MODES:
            self.waiting = todo
        if not todo or mode in WAITING_MODES:
            return None
        return self._compile(todo, mode, lock)

    def refresh(self, mode: str, query: bool, lock: threading.Lock) -> threading.Thread | None:
        """Swap in what reached the cache since; on a query in 'on_query' mode, build the rest.

        ('cached', 'on_query') Looks into the cache at most every CACHE_RECHECK_S.  ``query``: the
        solve is a query (``commit=False``); ``lock``: the solver's, which the caller holds.
        Returns the thread of a compile this started, else None.
        """
        if not self.waiting:
            return None
        if time.monotonic() - self._cache_checked > CACHE_RECHECK_S:
            self._cache_checked = time.monotonic()
            self.load_cached()
        if not (query and mode == "on_query" and self.waiting):
            return None
        todo, self.waiting = self.waiting, []
        return self._compile(todo, mode, lock)

    def _compile(self, todo: list, mode: str, lock: threading.Lock) -> threading.Thread | None:
        """Compile ``todo``'s (name, function, library) in order: now ('blocking') or in a thread.

        'background' runs the compiler niced (a stream's own model: the stream comes first);
        'on_query' at the process's priority (a query worker: its queries wait for it).
        """
        nlp = self.nlp

        def work(locked: bool) -> None:
            t0 = time.perf_counter()
            # the derivatives first, the outputs' function last
            for k, (name, fn, lib) in enumerate(todo):
                if self.retired:  # the scene was rebuilt: nothing more to compile for this one
                    return
                nice = 10 if mode == "background" else 0
                # with its active-set loop and the residual function that loop uses
                active = name == "kkt"
                # its -D settings: native_newton.active_flags
                flags = native_newton.active_flags(fn, nlp.residual_fn) if active else FLAGS
                native, ok = compiled(
                    fn,
                    nice=nice,
                    lib=lib,
                    flags=flags,
                    extra_source=native_newton.active_source(fn, nlp.residual_fn)
                    if active
                    else "",
                    also=(nlp.residual_fn,) if active else (),
                )
                loop = (
                    native_newton.build(nlp, nice=nice, kkt_lib=lib)
                    if ok and name == "kkt_free"
                    else None
                )
                # blocking: the caller may hold the solver's lock
                with threading.Lock() if locked else lock:
                    if not ok or self.retired:  # no compiler, or the scene was rebuilt meanwhile
                        return
                    self._install(name, native, fn, lib, loop)
                    if name != "outputs" and all(
                        later == "outputs" for later, _, _ in todo[k + 1 :]
                    ):
                        self.compiled = True  # every derivative runs compiled now
                        self.compile_time_s = time.perf_counter() - t0

        if mode == "blocking":
            work(locked=True)
            return None
        thread = threading.Thread(target=work, args=(False,), name="dlo-compile", daemon=True)
        thread.start()
        return thread

    def _load(self, name: str, fn: ca.Function, lib) -> bool:
        """Swap in the library ``lib`` of the function ``name`` if it is in the cache.

        Swap in the library ``lib`` of the function ``name`` if it is in the cache (for the
        contact-free function: with its Newton loop's library); False if it is not there yet.
        """
        native = native_newton.cached(self.nlp, kkt_lib=lib) if name == "kkt_free" else None
        own = load_native(lib, fn)  # checked by cache_store: None if missing or refused
        if own is None or (native is None and name == "kkt_free"):
            return False
        self._install(name, own, fn, lib, native)
        return True

    def _install(self, name: str, native, fn: ca.Function, lib, loop) -> None:
        """Put the compiled ``native`` of the function ``name`` in place.

        Put the compiled ``native`` of the function ``name`` in place: for the KKT functions
        (compiled split) with the Hessian's per-node part added (``native.newton.WithNodePart``),
        the contact-free one with its compiled Newton step and loop ``loop``, the full one with its
        active-set loop.
        """
        if name == "kkt_free":
            native = native_newton.WithNodePart(native, self.nlp.node_blocks, 0)
        if name == "kkt":  # the drivers in its library add its curvature blocks too
            sizes = self.nlp.contact_sizes
            self.nlp.node_blocks.attach_contact(sizes)
            native = native_newton.WithNodePart(native, self.nlp.node_blocks, 3, sizes)
        setattr(self, name, native)
        if name == "kkt_free":
            # built on first use: with the loop loaded (as a rule) it is never called
            interpreted = self.newton_step
            self.newton_step = DeferredFunction(
                lambda: self._compiled_newton_step(fn, lib, interpreted)
            )
            self.newton_native = loop
        if name == "kkt":
            self.newton_active = self._active_loop(lib)
            self.saddle_escape = native_saddle.load(lib, self.nlp)
        if name == "outputs":
            self.outputs_compiled = True
        self._attach()

    def _attach(self) -> None:
        """Let the compiled loops evaluate what a converged update needs beyond the loop.

        Let the compiled loops evaluate, in their own call, what a converged update needs beyond
        the loop: the obstacle rows (the contact-free loop) and the outputs, as far as those are
        compiled (``native.newton.UpdateOutputs``).
        """
        obstacle = self.obstacle_g if isinstance(self.obstacle_g, NativeFunction) else None
        outputs = self.outputs if isinstance(self.outputs, NativeFunction) else None
        if self.newton_native is not None and (obstacle is not None or outputs is not None):
            self.newton_native.after = native_newton.UpdateOutputs(self.nlp, obstacle, outputs)
        if self.newton_active is not None and outputs is not None:
            self.newton_active.after = native_newton.UpdateOutputs(self.nlp, None, outputs)

    def load_cached(self) -> bool:
        """Swap in the libraries that reached the cache since ``start_compile``.

        ('cached' mode) Swap in the libraries that reached the cache since ``start_compile``
        (another process or solver compiled them); True if anything was swapped in.  The caller
        holds the solver's lock.  A check costs a file lookup per missing library.
        """
        loaded = [item for item in self.waiting if self._load(*item)]
        if loaded:
            self.waiting = [item for item in self.waiting if item not in loaded]
            self.compiled = all(name == "outputs" for name, _, _ in self.waiting)
        return bool(loaded)

    def _active_loop(self, lib) -> native_newton.ActiveNewton | None:
        """Load the active-set Newton loop from the full KKT function's library.

        The active-set Newton loop in the full KKT function's library (None if it cannot be
        loaded).
        """
        try:
            return native_newton.ActiveNewton(
                lib,
                self.nlp.z_sym.shape[0],
                int(self.nlp.lbg.size),
                self.nlp.node_blocks,
                self.nlp.equality,
            )
        except (OSError, AttributeError):
            return None

    def _compiled_newton_step(
        self, split: ca.Function, lib, interpreted: InterpretedFunction | DeferredFunction
    ) -> InterpretedFunction:
        """Build ``newton_fn`` around the compiled split contact-free function.

        ``newton_fn`` around the compiled split contact-free function (``casadi.external``) plus
        the Hessian's per-node part (a CasADi product: this path serves only while the loop is
        missing); ``interpreted``, the one before, if the library cannot be loaded (then the steps
        are still right, only slower).
        """
        nlp = self.nlp
        try:
            external = ca.external(split.name(), str(lib))
        except RuntimeError:
            if isinstance(interpreted, DeferredFunction):
                return interpreted.built()
            return interpreted
        n, nf = nlp.z_sym.shape[0], nlp.n_free_rows
        z, p, lam = ca.MX.sym("z", n), ca.MX.sym("p", nlp.p_sym.shape[0]), ca.MX.sym("lam", nf)
        kkt, residual, grad, energies, weighted = external(z, p, lam)
        node = ca.mtimes(sparse(nlp.node_map).T, weighted)
        kkt = kkt + ca.blockcat([[node, ca.MX(n, nf)], [ca.MX(nf, n), ca.MX(nf, nf)]])
        return InterpretedFunction(
            newton_function(
                nlp, ca.Function("dlo_kkt_free", [z, p, lam], [kkt, residual, grad, energies])
            )
        )
