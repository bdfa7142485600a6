"""Whether an identified input gain is one an arm can have: the check ``project_g`` makes of
every identification step of the adaptive law (:class:`~apc_feedback.controller.
AdaptiveFeedback`), on the diagonal of Ĝ's velocity block (≈ T (D⁻¹)_ii).

``(D⁻¹)_ii > 0`` for any arm. Stricter tests do worse (``bench/preset_sweep.py``,
``bench/long_run.py``): positive definiteness of the whole block fails from the start on the
six-joint PUMA (Eq. 33's ``A B T²/2`` makes ``Ĝ(0)`` non-symmetric, wrist inertias are ~1e-4 of
the arm's); bounds relative to ``Ĝ(0)`` destabilise the Panda; and explaining a refused step's
residual as a jump of ``ŵ`` destabilises an hour-long run. Plain Python: no rclpy.
"""

from __future__ import annotations

import numpy as np

from apc_feedback.arrays import all_true

#: With ``relinearize``, ``project_g`` refuses an identification step that would leave a
#: diagonal entry of Ĝ's velocity block under this fraction of the current set point's prior
#: (Eq. 33 there) lower than it was: an arm ten times heavier about a joint than its model is
#: beyond any payload the prior leaves to the identifier. An entry the move to a new set point
#: took a little under may climb back; one under half of it (put there from outside: a
#: corrupted estimate) may move freely, so that the identifier can repair it. Scaling the
#: input's column back up instead, after a step or a move, kept the identification going but
#: let the off-diagonal entries grow until Ĝ pushed a direction the wrong way. In closed loop a
#: disturbance the law cancels (an unknown payload's torques along a move) makes the data say
#: the torque does nothing, and the PUMA's Ĝ₁₁ drifts from 0.7 of the prior (the payload's
#: true share) to 0 and below. Without ``relinearize`` the prior is the first set point's, from
#: which the Panda's true gain moves 0.19-6.9 times on a move: no relative bound there, only
#: the sign.
RELATIVE_GAIN_FLOOR = 0.1


def velocity_gain_physical(
    diagonal: np.ndarray, prior: np.ndarray | None, before: np.ndarray | None
) -> bool:
    """Whether ``diagonal`` (Ĝ's velocity block's, (n,)) is positive and, given the ``prior``'s
    diagonal at the current set point and the diagonal ``before`` the step (``relinearize``),
    no entry ends under :data:`RELATIVE_GAIN_FLOOR` of the prior's lower than it was, unless it
    was under half the floor already (put there from outside, it may move freely)."""
    if not all_true(diagonal > 0.0):
        return False
    if before is None:
        return True
    if prior is None:
        raise ValueError("a diagonal before the step needs the prior's")
    floor = RELATIVE_GAIN_FLOOR * prior
    return bool(all_true((diagonal > floor) | (diagonal >= before) | (before <= 0.5 * floor)))
