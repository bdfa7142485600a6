"""The adaptive feedback law; the interface every law implements is
:mod:`apc_feedback.feedback_law`.

- :class:`AdaptiveFeedback` — the paper's adaptive perturbation control: RLS identification of
  ``dx(k+1) = F dx(k) + G du(k) + w`` (Eqs. 16, 29-31) and the one-step optimal control of
  Eqs. 34-35, with ``F(0), G(0)`` from Eq. 33 at the first nominal point.
- :mod:`apc_feedback.baselines` — computed torque (Eq. 36), PD, none.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections import deque
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from apc_feedback.adaptive_config import MAX_INPUT_LAGS, AdaptiveConfig, FeedbackError
from apc_feedback.arrays import finite_array
from apc_feedback.feedback_law import FeedbackLaw, FeedbackOutput
from apc_feedback.input_gain_check import velocity_gain_physical
from apc_feedback.input_timing import InputTiming
from apc_feedback.lagged_control import (
    RING_CHECK_PERIOD_S,
    damped_input_change,
    input_change_cap,
    input_ringing,
    receding_controller,
    summed_inputs,
    write_identified,
)
from apc_feedback.linearize import SetpointLinearization, VelocityStencil, initial_model
from apc_feedback.optimal import OneStepControl, RecedingHorizonControl, validate_weights
from apc_feedback.rls import Rls, RlsError

#: With ``relinearize``, Eq. 33 is taken again at most this often (s of samples): an arm's
#: inertia changes on the time scale of a move, and at T = 1 ms taking it every sample cost the
#: 1 kHz robot path a third more late commands (``bench/robot_loop.py``) for a prior that moves
#: by a hundredth of a move's change.
RELINEARIZE_PERIOD_S = 0.01


class _Pending(NamedTuple):
    """An update's work left for :meth:`AdaptiveFeedback.settle` (``dx`` None: the gain only)."""

    k: int
    dx: np.ndarray | None
    identify: bool
    follow: bool
    q_d: np.ndarray
    qd_d: np.ndarray
    u_n: np.ndarray


class AdaptiveFeedback(FeedbackLaw):
    """Adaptive perturbation control (Eqs. 16, 29-35).

    Per sample ``k`` with ``dx(k) = (q - q_d, qd - qd_d)``:

    1. at the first sample, ``F̂(0), Ĝ(0)`` from Eq. 33 at ``(q_d(0), qd_d(0), u_n(0))`` on the
       controller's model, ``ŵ(0) = 0``, ``P(0) = alpha I`` (Eq. 32);
    2. otherwise one RLS step (Eqs. 29-31) with ``z(k-1) = (dx(k-1), du(k-1), 1)`` and target
       ``dx(k)``, where ``du(k-1)`` is the applied torque minus ``u_n(k-1)``; only if the
       previous sample handled was ``k - 1``: after a gap (samples lost on the network, a
       controller restarted) the step spans several periods and would teach the identifier a
       model that is not Eq. 16's, so it is skipped and the estimate kept;
    3. ``du(k) = -(R + ĜᵀQĜ)⁻¹ĜᵀQ(F̂ dx(k) + ŵ)`` (Eq. 35, exact minimiser of Eq. 34).

    Within the same structure (identified model, optimal control of it) two extensions can be
    switched on: a receding horizon of N steps (``horizon``) and integral action on the
    position error (``q_integral``), which augments the identified model with
    ``ξ(k+1) = ξ(k) + T C (F̂ dx + Ĝ du + ŵ)`` (C selects the position rows).

    ``defer_learning`` (robot mode's ``command_first``; off: the paper's order): with a receding
    plan ``du(k)`` is the gain planned after sample ``k-1`` on the state at ``k``; the step to
    ``k``, the prior's move and the next plan wait for :meth:`settle`. Åström and Wittenmark's
    order (*Computer-Controlled Systems*, on implementation: the output right after the input),
    for a model a sample older; the output reports the step taken after the last command.

    Parameters
    ----------
    model : pinocchio.Model
        The controller's model (never the plant's).
    config : AdaptiveConfig
    """

    kind = "adaptive"

    def __init__(self, model: pin.Model, config: AdaptiveConfig) -> None:
        super().__init__(model.nv)
        self.model = model
        limit = np.asarray(model.effortLimit, dtype=float)
        self._effort_limit = np.where((limit > 0.0) & np.isfinite(limit), limit, np.inf)
        self._effort_floor = -self._effort_limit
        self._data = model.createData()
        self._configured_lags = config.input_lags
        self._build_identifier(config)
        # The prior moves every RELINEARIZE_PERIOD_S of samples (each sample at T >= 10 ms).
        self._relinearize_every = max(1, round(RELINEARIZE_PERIOD_S / config.period))
        self._next_relinearize = 0
        self._ring_check_every = max(1, round(RING_CHECK_PERIOD_S / config.period))
        self.input_timing = InputTiming(config.input_delay)
        # (k, δu) another law sent while this one was idle: on their way at its next start.
        self._observed: deque[tuple[int, np.ndarray]] = deque(maxlen=MAX_INPUT_LAGS + 1)
        self.defer_learning = False  # the class docstring
        self._set_weights(config)
        self.reset()

    def _build_identifier(self, config: AdaptiveConfig) -> None:
        """The identifier and the prior's linearisation for ``config.input_lags``."""
        self.rls = Rls(self.n_joints, config.rls_config(self.n_joints), config.input_lags)
        self._setpoint_model = (
            SetpointLinearization(
                self.model, config.period, config.initial_model, config.input_lags
            )
            if config.relinearize
            else None
        )

    def _set_weights(self, config: AdaptiveConfig) -> None:
        """Everything derived from the config's weights and forms (not identifier state)."""
        n = self.n_joints
        q_diagonal = np.concatenate([np.full(n, config.q_position), np.full(n, config.q_velocity)])
        Q, R = np.diag(q_diagonal), config.r * np.eye(n)
        validate_weights(Q, R, 2 * n, n)
        self.config, self.Q, self.R = config, Q, R
        self._one_step = OneStepControl(q_diagonal, R, config.control_form)
        self._receding = receding_controller(config, q_diagonal, R, n)
        self._change_weight = np.zeros((n, n))
        # The input change's weight in use: q_input_change, raised by _damp_input_ringing.
        self.input_change_weight = config.q_input_change
        self._next_ring_check: int | None = None  # the plan judged at the next sample
        self._identify_applied = config.identify_with == "applied"
        self._gain: np.ndarray | None = None  # defer_learning: planned for the next sample

    @property
    def settings(self) -> AdaptiveConfig:
        return self.config

    def reconfigure(self, config: AdaptiveConfig) -> None:
        """Take new weights (``q_position``, ``q_velocity``, ``r``, ``q_input_change``,
        ``input_ring_limit``) at the next sample and keep what was identified; the identifier's
        own settings cannot change while it runs.

        Raises
        ------
        FeedbackError
            ``config`` changes a setting of the identifier (rho, alpha, forgetting,
            trace_max).
        """
        if config.input_lags != self._configured_lags:
            raise FeedbackError("the identifier's settings cannot change while it runs")
        config = dataclasses.replace(config, input_lags=self.config.input_lags)  # as sized
        if config.rls_config(self.n_joints) != self.config.rls_config(self.n_joints):
            raise FeedbackError("the identifier's settings cannot change while it runs")
        self._set_weights(config)

    def reset(self) -> None:
        n = self.n_joints
        self._started = False
        self._prior_input_gain: np.ndarray | None = None
        self._prior_model: np.ndarray | None = None  # [F G] of the prior the estimate is about
        self.rejected_updates = 0
        self.projected_updates = 0
        self.skipped_updates = 0
        self.stuck_updates = 0
        self._speed_prev = np.zeros(n)
        self._k_prev = 0
        # z(k-1) = (dx(k-1), du(k-1), 1) of Eq. 23, filled in place: dx(k) goes into its first
        # 2n entries once du(k) is known, du(k-1) is written when sample k arrives. With lags
        # the inputs are du(k-1), …, du(k-1-L), newest first; ``_inputs_known`` counts how
        # many of them are the perturbations actually applied (a gap leaves them unknown).
        lags = self.config.input_lags
        self._z = np.zeros(self.rls.m)
        self._z[-1] = 1.0
        self._z_dx, self._z_du = self._z[: 2 * n], self._z[2 * n : -1]
        self._inputs = self._z_du.reshape(lags + 1, n)
        self._inputs_known = 0
        self._dx = np.empty(2 * n)
        self._dx_q, self._dx_qd = self._dx[:n], self._dx[n:]
        self._du_prev = np.zeros(n)
        self._u_n_prev = np.zeros(n)
        self.integral = np.zeros(n)
        self.input_change_weight, self._next_ring_check = self.config.q_input_change, None
        # defer_learning: the next gain, the work left after a command, that step's report.
        self._gain = self._pending = self._settled = None

    def update(
        self,
        k: int,
        q: np.ndarray,
        qd: np.ndarray,
        q_d: np.ndarray,
        qd_d: np.ndarray,
        qdd_d: np.ndarray,
        u_n: np.ndarray,
        applied: np.ndarray | None,
    ) -> FeedbackOutput:
        if self._pending is not None:
            self.settle()  # the caller did not: the step after the last command, now
        dx = self._dx
        np.subtract(q, q_d, out=self._dx_q)
        np.subtract(qd, qd_d, out=self._dx_qd)
        # One reduction instead of an isfinite per entry (a sum past 1e308 counts as not finite).
        if not math.isfinite(float(np.add.reduce(dx))):
            raise FeedbackError(f"state error is not finite at sample {k}")
        residual = None
        rejected = skipped = identify = False
        stuck = self._stuck(qd)
        trace_p = float("nan")
        starting = not self._started
        if starting:
            self.input_timing.begin(choose=self.config.relinearize and bool(self.config.input_lags))
            lags = self.input_timing.lags(self._configured_lags, self.config.period)
            if lags != self.config.input_lags:  # the driver's timing needs another model size
                config = dataclasses.replace(self.config, input_lags=lags)
                self._build_identifier(config)
                self._set_weights(config)
                self.reset()
            self._prior_model = None
            if self._setpoint_model is not None:  # relinearize: the same series every sample
                prior = self._setpoint_model(
                    q_d, qd_d, u_n, self.split_delay(), self.input_timing.stencil
                )
                F0, G0 = prior[:, : 2 * self.n_joints], prior[:, 2 * self.n_joints :]
                self._prior_model = prior
                self._next_relinearize = k + self._relinearize_every
                models = self.input_timing.candidates(prior, self._setpoint_model.with_delay)
                self.input_timing.choice.start(self.input_timing.delay, models)
            else:
                F0, G0 = self._linearize(q_d, qd_d, u_n)
            held = self.input_timing.holds_split(self.config.input_lags, self.config.period)
            self.rls.reset(F0, G0, P0=self.config.initial_p(G0, self.n_joints, held))
            self._prior_input_gain = summed_inputs(G0, self.n_joints)
            # Before the first sample the arm is taken to hold its nominal torque (δu = 0), as
            # Eq. 16's first step takes it: identification starts at sample 1 with or without lags.
            self._inputs.fill(0.0)
            for k_sent, du_sent in self._observed:  # a fallback's commands still on their way
                if 0 <= k - 1 - k_sent < len(self._inputs):
                    self._inputs[k - 1 - k_sent] = du_sent
            self._observed.clear()
            self._inputs_known = lags
            self._started = True
        elif k != self._k_prev + 1:
            skipped = True
            self.skipped_updates += 1
            self._inputs_known = 0
        elif stuck:
            self.stuck_updates += 1
            self._shift_inputs(applied)
        elif not self._shift_inputs(applied):
            skipped = True  # the inputs of a lag are not known yet (after a start or a gap)
            self.skipped_updates += 1
        else:
            identify = True
        follow = self._prior_model is not None and not starting and k >= self._next_relinearize
        if follow:
            self._next_relinearize = k + self._relinearize_every
        gain = self._gain
        if gain is not None and not starting:  # defer_learning: the plan of the sample before
            du = self._receding_control(dx, gain)
            self._pending = _Pending(
                k, dx.copy(), identify, follow, q_d.copy(), qd_d.copy(), u_n.copy()
            )
            residual, trace_p, rejected = self._settled or (residual, trace_p, rejected)
            self._settled = None
        else:
            self._settled = None  # this step reports itself
            if identify:
                residual, trace_p, rejected = self._identify(dx)
            if follow:
                self._follow_setpoint(q_d, qd_d, u_n)
            check = self._next_ring_check
            if check is None:  # a (re)start or new weights: judged before this sample's command
                self._damp_input_ringing(k, solved=False)
            du = self._control(dx)
            if check is not None and k >= check:  # this sample's plan; a raised weight next
                self._damp_input_ringing(k, solved=True)
            self._z_dx[:] = dx
            if self.defer_learning and self._receding is not None:
                self._pending = _Pending(k, None, False, False, q_d, qd_d, u_n)  # plan the gain
        if trace_p != trace_p:  # NaN: no accepted update this sample
            trace_p = self.rls.trace_p
        self._du_prev = du
        self._u_n_prev[:] = u_n
        self._k_prev = k
        return FeedbackOutput(du, residual, trace_p, rejected, skipped)

    def settle(self) -> None:
        """``defer_learning``, after a command (else the next update): the step, the prior's move,
        the next gain. A failing step raises and makes the next sample a gap; without a plan
        (new weights since, one that cannot be solved) the next sample plans first."""
        pending, self._pending = self._pending, None
        if pending is None:
            return
        self._gain = None
        if pending.dx is not None:
            try:
                if pending.identify:
                    self._settled = self._identify(pending.dx)
                if pending.follow:
                    self._follow_setpoint(pending.q_d, pending.qd_d, pending.u_n)
            except ValueError:  # as an update that fails: the next sample is a gap
                self._k_prev = pending.k - 1
                raise
            self._z_dx[:] = pending.dx
        # ControlError (R + BᵀPB not positive definite) or new weights since: no gain.
        with contextlib.suppress(ValueError):
            if self._next_ring_check is not None:
                self._gain = self._plan_gain(pending.k)

    def _identify(self, dx: np.ndarray) -> tuple[np.ndarray | None, float, bool]:
        """One RLS step to ``dx`` from ``z``: residual, ``trace(P)`` (NaN: none), refused."""
        residual, trace_p = None, float("nan")
        try:
            before = (
                self._velocity_gain().diagonal().copy()
                if self.config.project_g and self._prior_model is not None
                else None
            )
            if self.input_timing.choice.active:
                self.input_timing.choice.score(dx, self._z[:-1], self.n_joints)
            step = self.rls.update(self._z, dx)
            residual, trace_p = step.residual, step.trace_p
            if self.config.project_g and not self._g_physical(before):
                # Unphysical Ĝ: take the step back, keep the last physical estimate.
                self.rls.undo()
                self.projected_updates += 1
                trace_p = self.rls.trace_p
        except RlsError:  # keep controlling with the last good estimate; the node counts it
            self.rejected_updates += 1
            return residual, trace_p, True
        return residual, trace_p, False

    def _plan_gain(self, k: int) -> np.ndarray:
        """The plan's gain over ``(δx, δu on their way, ξ, 1)`` after sample ``k``, its input
        ringing judged when due (a raised weight planned again)."""
        gain = self._write_plan().gain()
        if self._next_ring_check is not None and k >= self._next_ring_check:
            weight = self.input_change_weight
            self._damp_input_ringing(k, solved=True)  # reuses the recursion gain() ran
            if self.input_change_weight != weight:
                gain = self._write_plan().gain()
        return gain

    def split_delay(self) -> float:
        """The modelled delay (s) from a sample to its command acting (0 without lags)."""
        return self.input_timing.delay if self.config.input_lags else 0.0

    def _linearize(
        self, q_d: np.ndarray, qd_d: np.ndarray, u_n: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 33's ``F, G`` at a set point, ``G`` split by the expected delay with lags."""
        return initial_model(
            self.model,
            q_d,
            qd_d,
            u_n,
            self.config.period,
            self.config.initial_model,
            delay=self.split_delay(),
            input_lags=self.config.input_lags,
            stencil=self.input_timing.stencil,
            data=self._data,
        )

    def _follow_setpoint(self, q_d: np.ndarray, qd_d: np.ndarray, u_n: np.ndarray) -> None:
        """Move the estimate with its prior to this sample's set point (``relinearize``): the
        identification step just taken was about the previous sample's prior."""
        assert self._setpoint_model is not None and self._prior_model is not None
        assert self._prior_input_gain is not None
        prior = self._setpoint_model(q_d, qd_d, u_n, self.split_delay(), self.input_timing.stencil)
        self.input_timing.choice.moved(
            self.input_timing.candidates(prior, self._setpoint_model.with_delay)
        )
        n, p = self.n_joints, 2 * self.n_joints
        gain = summed_inputs(prior[:, p:], n)
        delta = prior - self._prior_model
        # Ĝ moves with its prior's change in input space, Ĝ_j ← Ĝ_j Gv⁻¹ Gv' (Gv, Gv': the
        # old and new prior's summed velocity blocks, ≈ T D⁻¹), so Ĝ Gv⁻¹ is kept: what the arm
        # does with a torque relative to what the model says (a payload's share) keeps its
        # proportion, where an added deviation would not (the PUMA's Ĝ₁₁, identified at 0.1-0.2
        # of the prior with the unknown payload, would change sign as the prior falls to 0.74
        # of it on the move).
        transport = np.linalg.solve(self._prior_input_gain[n:], gain[n:])
        estimate = self.rls.model_view()[:, p:-1]
        moved = np.matmul(estimate.reshape(p, -1, n), transport).reshape(p, -1)
        np.subtract(moved, estimate, out=delta[:, p:])
        self.rls.shift_model(delta)
        self._prior_model = prior
        self._prior_input_gain = gain

    @property
    def prior_input_gain(self) -> np.ndarray | None:
        """Eq. 33's ``G(0)`` at the first sample since the last :meth:`reset` (the effect of a
        perturbation held over one period), shape (2n, n); with ``relinearize`` Eq. 33's ``G``
        at the set point the prior last moved to; None before the first sample."""
        return self._prior_input_gain

    @property
    def identified_input_gain(self) -> np.ndarray:
        """The identified effect of a perturbation held over one period (with lags, the sum
        of ``Ĝ₀ … Ĝ_L``), shape (2n, n): what :attr:`prior_input_gain` started it from."""
        return self._input_gain()

    def expect_input_delay(
        self, seconds: float, candidates: Sequence[float] = (), exact: bool = False
    ) -> None:
        """Split ``Ĝ(0)`` by this delay (s), from a sample to the arm applying its command, at
        the next (re)start instead of ``config.input_delay`` (no effect without lags).
        ``candidates``: other delays the arm may have (a drive that adds a cycle); with
        ``relinearize`` each is scored by how well its prior predicts the arm, and a restart
        takes the clearly best (:class:`apc_feedback.input_timing.DelayChoice`). ``exact``:
        measured (robot mode, from the driver's effort): the split is held
        (:data:`HELD_SPLIT_PRIOR`), only the total input gain learnt."""
        self.input_timing.expect_delay(seconds, candidates, exact)

    def observe_command(self, k: int, u_n: np.ndarray, du: np.ndarray) -> None:
        """Another law (a fallback) sent ``u_n + du`` at sample ``k`` while this one is idle:
        with lags, its next start plans with the commands still on their way as they are, not
        as ``u_n`` (δu = 0). A fallback holding an unknown payload sends 10-20 N m more than
        ``u_n``; on a 100 Hz driver with a drive that adds a cycle four of its commands are in
        flight at a hand-back."""
        if self.config.input_lags:
            command = np.clip(u_n + du, self._effort_floor, self._effort_limit)
            self._observed.append((k, command - u_n))

    def move_nominal(self, shift: np.ndarray) -> None:
        """From the next sample ``u_n`` is ``shift`` (shape (n,)) higher for the same torque
        on the arm (robot mode carrying an estimated payload, whose load the law held): every
        ``δu`` the law remembers is measured from the new ``u_n`` (the regressor's inputs, the
        last command, a fallback's commands on their way) and ``ŵ`` takes what they held
        (:meth:`apc_feedback.rls.Rls.move_input_origin`). The identified model predicts as
        before and the integral, ``F̂``, ``Ĝ`` and ``P`` stay: the next command is the one
        the law would have sent, but for ``R`` of Eq. 34 now weighing ``δu`` from the new
        ``u_n``. Raises :class:`FeedbackError` on a wrong shape or a non-finite entry."""
        shift = finite_array("shift", shift, (self.n_joints,), FeedbackError)
        self.rls.move_input_origin(shift)
        self._inputs -= shift  # in place: they are the regressor's
        self._u_n_prev += shift
        self._du_prev = self._du_prev - shift  # a new array: the last output's du is the caller's
        for i, (k_sent, du_sent) in enumerate(self._observed):
            self._observed[i] = (k_sent, du_sent - shift)
        self._gain = None  # defer_learning: a plan made on the old origin is made again
        if self._pending is not None:  # and the re-linearisation left to do is at the new u_n
            self._pending = self._pending._replace(u_n=self._pending.u_n + shift)

    def restart(self) -> None:
        """:meth:`reset`, keeping this law's commands still on their way (with lags, its next
        start plans with them as with a fallback's, :meth:`observe_command`): for a change of
        what it is told of its samples while it commands."""
        if not (self._started and self.config.input_lags):
            self.reset()
            return
        k, u_n, du = self._k_prev, self._u_n_prev, self._du_prev
        older = [(k - 1 - j, row.copy()) for j, row in enumerate(self._inputs)]
        self.reset()  # new arrays: u_n and du above stay as they were
        self._observed.extend(older)
        self.observe_command(k, u_n, du)  # the newest, within the effort limits

    def expect_velocity_stencil(self, stencil: VelocityStencil | None) -> None:
        """From the next (re)start, the samples' velocity is ``stencil`` of past positions
        (robot mode's estimate for a driver that sends none; None: a measured velocity): the
        prior is the model of such a sample (:func:`apc_feedback.linearize.sampled_coordinates`),
        whose inputs act over the stencil's span as well. No effect on a model without lags."""
        self.input_timing.expect_stencil(stencil)

    def _g_physical(self, before: np.ndarray | None = None) -> bool:
        """:func:`~apc_feedback.input_gain_check.velocity_gain_physical` of Ĝ now (``before``:
        the diagonal before the step, with ``relinearize``)."""
        prior = self._prior_input_gain
        return velocity_gain_physical(
            self._velocity_gain().diagonal(),
            None if prior is None else prior[self.n_joints :].diagonal(),
            before,
        )

    def _velocity_gain(self) -> np.ndarray:
        """Ĝ's velocity block (with lags, their sum), (n, n); a view without lags."""
        n = self.n_joints
        if self.config.input_lags:
            return self._input_gain(velocity_rows=True)
        # Θᵀ = [F G w]: Ĝ's velocity block is rows n..2n, columns 2n..3n.
        return self.rls.model_view()[n : 2 * n, 2 * n : 3 * n]

    def _input_gain(self, velocity_rows: bool = False) -> np.ndarray:
        """:attr:`identified_input_gain` (a fresh array) from the identifier's Θᵀ without a
        copy of it; with ``velocity_rows`` only its velocity block (rows n..2n)."""
        n = self.n_joints
        rows = slice(n, 2 * n) if velocity_rows else slice(0, 2 * n)
        return summed_inputs(self.rls.model_view()[rows, 2 * n : -1], n)

    def _control(self, dx: np.ndarray) -> np.ndarray:
        """Optimal control of the identified model (Eq. 35, or a receding horizon's)."""
        if self._receding is None:
            return self._one_step(self.rls.model_view(), dx)
        return self._receding_control(dx)

    def _receding_control(self, dx: np.ndarray, gain: np.ndarray | None = None) -> np.ndarray:
        """The receding-horizon control over ``(δx(k), δu(k-1), …, δu(k-L), ξ(k+1))``.

        With ``L`` input lags ``δx(k+1) = F δx + G₀ v + Σ_j G_j δu(k-j) + w``, ``v = δu(k)``;
        the inputs shift one lag per step. The horizon counts ``horizon`` steps after the longest
        lag, so the decision is weighed where it has acted. With integral action the model is
        augmented with ``ξ(k+1) = ξ(k) + T C (F̂ δx + Ĝ δu + ŵ)`` (C: the position rows).
        :meth:`_write_plan` writes the model; a ``gain`` planned before is applied instead.
        """
        config, n = self.config, self.n_joints
        p, s = 2 * n, (2 + config.input_lags) * n  # s: the state without the integral
        control = self._write_plan() if gain is None else self._receding
        assert control is not None
        x = control.x
        x[:p] = dx
        # After this sample's identification step the inputs hold δu(k-1), …, δu(k-1-L).
        x[p:s] = self._z_du[: s - p]
        if config.q_integral > 0.0:
            x[s:] = self._integrate(dx)
        return control.solve() if gain is None else control.input_for(gain)

    def _write_plan(self, weight: float | None = None) -> RecedingHorizonControl:
        """The receding-horizon controller with the identified model written into it
        (:func:`apc_feedback.lagged_control.write_identified`), the input change weighed at
        ``weight`` (default: ``q_input_change`` as :meth:`_damp_input_ringing` raised it)."""
        config, control = self.config, self._receding
        assert control is not None
        lags = config.input_lags
        weight = self.input_change_weight if weight is None else weight
        gain = self._velocity_gain() if lags >= 2 and weight > 0.0 else None
        integral = config.period if config.q_integral > 0.0 else 0.0
        model = self.rls.model_view()
        write_identified(control, model, lags, integral, gain, weight, self._change_weight)
        return control

    def _damp_input_ringing(self, k: int, solved: bool) -> None:
        """Raise the weight of the input's change until the law's own inputs do not ring
        (:func:`apc_feedback.lagged_control.damped_input_change`, ``input_ring_limit``), and
        check again ``RING_CHECK_PERIOD_S`` after sample ``k``; ``solved``: first judged on the
        plan this sample's command came from (its recursion reused: a small solve)."""
        self._next_ring_check = k + self._ring_check_every
        config, control = self.config, self._receding
        limit, lags = config.input_ring_limit, config.input_lags
        if limit <= 0.0 or control is None or lags < 2 or self.input_change_weight <= 0.0:
            return  # nothing to raise
        weight, cap = self.input_change_weight, input_change_cap(config.q_input_change)
        if solved:  # this sample's plan: judged at its weight already
            if input_ringing(control, lags, reuse=True) <= limit:
                return
            weight = min(2.0 * weight, cap)
        self.input_change_weight = damped_input_change(self._write_plan, weight, lags, limit, cap)

    def _integrate(self, dx: np.ndarray) -> np.ndarray:
        """This sample's integration step of the position error, ``ξ ← ξ + T δq`` within the
        anti-windup bound ``integral_limit``; the new ``ξ``."""
        T, limit = self.config.period, self.config.integral_limit
        # np.clip's own wrapper costs more than the two ufuncs it is (the same bits).
        step = self.integral + T * dx[: self.n_joints]
        self.integral = np.minimum(np.maximum(step, -limit), limit)
        return self.integral

    def _stuck(self, qd: np.ndarray) -> bool:
        """A joint's measured speed is below ``identify_min_speed`` at ``k-1`` or ``k``."""
        v_min = self.config.identify_min_speed
        if v_min <= 0.0:
            return False
        speed = np.abs(qd)
        stuck = bool((np.minimum(speed, self._speed_prev) < v_min).any())
        self._speed_prev = speed
        return stuck

    def _shift_inputs(self, applied: np.ndarray | None) -> bool:
        """Enter ``δu(k-1)`` into the regressor's inputs, the older ones one lag down; whether
        all of them are known.

        Without lags ``δu(k-1)`` is the torque the plant reports it applied over
        ``[(k-1)T, kT)`` minus ``u_n(k-1)`` (or the command). With lags it is the command sent
        at ``k-1``, within the model's effort limits, minus ``u_n(k-1)``: the lags model when
        a command takes effect, and a report of what was applied has the delay in it already.
        """
        inputs = self._inputs
        if len(inputs) > 1:
            inputs[1:] = inputs[:-1]  # numpy copies an overlapping source first
            # Within the effort limits (np.clip's own wrapper costs more than its two ufuncs).
            command = np.add(self._u_n_prev, self._du_prev, out=inputs[0])
            np.maximum(command, self._effort_floor, out=command)
            np.minimum(command, self._effort_limit, out=command)
            np.subtract(command, self._u_n_prev, out=command)
        elif applied is not None and self._identify_applied:
            np.subtract(applied, self._u_n_prev, out=inputs[0])
        else:
            inputs[0] = self._du_prev
        self._inputs_known = min(self._inputs_known + 1, len(inputs))
        return self._inputs_known == len(inputs)
