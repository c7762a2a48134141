"""Which shape a self-contact stream may take as its topology reference (issue #35).

A warm update of a model with self-contact is checked against the committed shape (``ShapeSolver``:
crossing signs, the straight sweep from the committed shape, the clamped span's linking number),
and a refused update leaves that shape committed, so that the next target is solved from the last
good shape.  That holds only if the committed shape is one the string can take.  A shape that
passes through itself is not: from it, every shape that does not is "not reached without the string
passing through itself", every later update is refused, and the stream stays frozen until a reset
(the wedge of #35: auto switched to its self-contact model at a closed loop whose answer without
self-contact, a planar figure eight, had its strands 2.2 mm apart where the rows keep D = 10.6 mm,
and adopted that answer as the new model's committed shape).

Two rules, both made of the self-contact module's own tests (``self_contact.py``):

* ``why_not_reference``: a shape that penetrates itself, or that the straight sweep from the last
  verified shape does not reach without two samples meeting, is not a topology reference.  auto
  then switches to its self-contact model from the last verified shape instead
  (``AutoShapeSolver``), and solves the update from there with every check a warm update has.
* ``through_itself``: a warm start that carries no self-contact state (mapped from a model without
  self-contact) and penetrates itself is no reference either: an update from it is checked as a
  cold start is (the answer must not penetrate itself); that answer, once committed, is the
  reference.
"""

from __future__ import annotations

import numpy as np

from ..contact import self_contact as SC

#: how far below D a sample pair may come before it counts as penetrating, as a fraction of L (the
#: slack ``ShapeSolver`` allows a self-contact row)
SLACK = 1e-7


def through_itself(
    candidates: list[tuple[tuple[int, int], float]], geometry: SC.ContactGeometry, length: float
) -> bool:
    """Tell whether a shape whose ``candidate_pairs`` are ``candidates`` penetrates itself.

    It does when a pair is closer than the distance D the self-contact rows keep, less
    ``SLACK``·L (``length``: L [m]).
    """
    return bool(SC.penetrations(candidates, geometry, SLACK * length))


def why_not_reference(
    before: np.ndarray | None, after: np.ndarray, geometry: SC.ContactGeometry, length: float
) -> str:
    """Return why the shape sampled at ``after`` cannot be a topology reference ('' if it can).

    ``after``: (N, 3) points [m] at ``geometry.s``; the reference is that of a self-contact
    stream whose last verified shape is ``before`` (the same samples, or None).  It cannot when
    it penetrates itself, or when moving every sample straight from ``before`` to it makes two of
    them meet (``self_contact.swept_crossing``: the string may have passed through itself on the
    way).
    """
    candidates = SC.candidate_pairs(after, geometry)
    through = SC.penetrations(candidates, geometry, SLACK * length)  # as through_itself
    if through:
        a, b = through[0]
        d = dict(candidates)[(a, b)]
        return (
            f"it passes through itself (s = {geometry.s[a]:.4g} m and {geometry.s[b]:.4g} m "
            f"are {d:.3g} m apart, the rows keep {geometry.distance:.3g} m)"
        )
    if before is not None:
        swept = SC.swept_crossing(before, after, geometry)
        if swept is not None:
            a, b = swept
            return (
                f"it is not reached from the last shape without the string passing through "
                f"itself (s = {geometry.s[a]:.4g} m and {geometry.s[b]:.4g} m meet on the "
                f"way)"
            )
    return ""
