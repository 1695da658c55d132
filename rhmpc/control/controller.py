"""The controller a robot runs: the reference, the observer, the MPC and the cancellation.

Two calls make the whole controller, the same for this Python reference and for the C code that
``rhmpc export`` generates from it (:mod:`rhmpc.control.export`)::

    controller.refresh(tick, z, stamp)     a sensor sample's arrival: gate → predictor →
                                           interpolation (:mod:`rhmpc.control.reference`)
    controller.forecast(tick, stamp, pts)  or a forecast made outside (another process):
                                           interpolation, in place of the refresh's own
    tau = controller.step(tick, q)         every control tick, from the encoders' angles q̃

A step, with the reference's points r_{i+1..i+N} of tick i::

    x̂ = observer.correct(q̃)                         x̂ = [q − q0; q̇]  (:mod:`.observer`)
    u = mpc.step(x̂, r)                               τ_mpc            (:mod:`.mpc`)
    τ_c = u + ĝ(q̄) + Ĉ(q̄, q̂̇) q̂̇ + f̂(q̂̇)               the controller's model (:mod:`.cancellation`)
    τ = clip(τ_c, −τ_max, τ_max)                     what the actuators can apply
    observer.predict(u_{i−d} + (τ − τ_c)_{i−d})     the MPC torque that acts over the tick

``d`` is the input delay in ticks (the torque computed on tick i acts from tick i + d); the
observer predicts with the torque that acts, including what the clip took off it. ``q̄`` is the
reading the observer fused: the encoders' angles, or the prediction for a joint whose reading
it held out (past its innovation gate, or not finite). While a joint has been held for the
observer's ``fault_timeout`` (an encoder fault), the MPC brakes instead of tracking
(``mpc.brake``, failure ``encoder_fault``). A command that is not finite holds the last torque.
"""

from __future__ import annotations

import collections
import time

import numpy as np

clock = time.perf_counter_ns

__all__ = ["Controller"]


class Controller:
    """Reference, observer, MPC and cancellation behind ``refresh`` and ``step``.

    Parameters
    ----------
    mpc : rhmpc.control.mpc.RecedingHorizonMPC
        The MPC (its ``stats`` are the controller's).
    reference : PredictedReference or ExactReference
        The reference, already placed in the workspace (``place``).
    observer : rhmpc.control.observer.JointObserver
        x̂ from the encoders.
    cancellation : rhmpc.control.cancellation.NonlinearityCancellation or None
        ĝ + Ĉq̇ + f̂ from the controller's model; None: nothing to cancel (a linear plant).
    torque_limit : ndarray (nu,)
        abs(τ) the actuators apply [N·m].
    input_delay : int
        Ticks from a torque's computation to its action (0: it acts over the next tick).
    """

    def __init__(self, mpc, reference, observer, cancellation, torque_limit: np.ndarray,
                 input_delay: int = 0) -> None:
        if isinstance(input_delay, bool) or not isinstance(input_delay, int) or input_delay < 0:
            raise ValueError(f"input_delay must be an integer >= 0 [ticks], got {input_delay!r}")
        self.mpc, self.reference, self.observer = mpc, reference, observer
        self.cancellation = cancellation
        self.torque_limit = np.asarray(torque_limit, dtype=float).copy()
        self._bounds = list(zip((-self.torque_limit).tolist(), self.torque_limit.tolist(),
                                strict=True))
        self.input_delay = input_delay
        self.nu = self.torque_limit.size
        self.N = mpc.N
        self.reset()

    def reset(self) -> None:
        """At rest at the home posture: no plan, no points, zero counters."""
        self.mpc.reset()
        self.reference.reset()
        self.observer.reset()
        zero = np.zeros(self.nu)
        #: the last step's MPC torque u, commanded torque τ_c and applied torque τ [N·m]
        self.u, self.tau_command, self.tau = zero, zero, zero
        self.saturated = False  # whether the last step's τ_c was clipped
        self._acting = collections.deque([zero] * self.input_delay)
        #: the time of the last step and of the last refresh [ns]
        self.step_ns = self.refresh_ns = 0

    @property
    def stats(self):
        """The MPC's counters (:class:`rhmpc.control.fallback.MPCStats`)."""
        return self.mpc.stats

    @property
    def predictor_counts(self) -> dict:
        """The predictor's and the gate's event counts (empty without a predictor)."""
        predictor = getattr(self.reference, "predictor", None)
        return {} if predictor is None else dict(predictor.counts)

    @property
    def outliers(self) -> tuple[int, int]:
        """(samples the gate rejected, samples retracted after the fact) so far."""
        counts = getattr(getattr(self.reference, "predictor", None), "counts", None) or {}
        return counts.get("outliers_rejected", 0), counts.get("retracted", 0)

    @property
    def encoder_counts(self) -> dict:
        """The observer's events: ``held`` (joint readings held out), ``reacquired``."""
        return dict(self.observer.counts)

    @property
    def gate_floor(self) -> float | None:
        """The outlier gate's floor [m] (None without a gate, or while it calibrates)."""
        gate = getattr(self.reference, "gate", None)
        return None if gate is None else gate.floor

    @property
    def mean_age(self) -> float:
        """Mean age of the newest sample when a forecast is made from it [s] (NaN if none)."""
        return getattr(self.reference, "mean_age", float("nan"))

    @property
    def x_hat(self) -> np.ndarray:
        """The last step's state estimate [q − q0; q̇] (the observer's storage)."""
        return self.observer.x

    def refresh(self, tick: int, z: np.ndarray | None, stamp: float,
                others: np.ndarray | None = None) -> None:
        """A sensor sample's arrival on ``tick``: ``z`` measured at ``stamp`` [s] (None: no new
        sample), ``others`` the other tracked points' samples (see
        :meth:`rhmpc.control.reference.PredictedReference.refresh`)."""
        start = clock()
        self.reference.refresh(tick, z, stamp, others)
        self.refresh_ns = clock() - start

    def forecast(self, tick: int, stamp: float, points: np.ndarray) -> bool:
        """A forecast made outside arriving on ``tick``: ``points[k]`` the centred POI at
        ``stamp + k·dt`` [m] (see :meth:`rhmpc.control.reference.PredictedReference.forecast`);
        returns whether it was taken."""
        start = clock()
        taken = self.reference.forecast(tick, stamp, points)
        self.refresh_ns = clock() - start
        return taken

    def horizon(self, tick: int) -> np.ndarray:
        """The reference's points r_{tick+1..tick+N} (N, 3) [m] (a read-only view)."""
        return self.reference.horizon(tick)

    def step(self, tick: int, q: np.ndarray) -> np.ndarray:
        """One control tick from the encoders' joint angles ``q`` [rad]: the torque τ to apply
        [N·m], within ±``torque_limit``."""
        start = clock()
        observer = self.observer
        x_hat = observer.correct(q)
        if observer.faulted:
            u = self.mpc.brake(x_hat)
        else:
            u = self.mpc.step(x_hat, self.reference.horizon(tick))
        command = u if self.cancellation is None else self.cancellation.torque(
            observer.reading, x_hat[self.nu :], u)
        if not np.isfinite(np.vdot(command, command)):  # the cancellation of a faulty reading
            command = self.tau  # hold the last torque
        commanded = command.tolist()  # the clip on floats: a 3-vector is cheaper so
        clipped = [min(max(c, lo), hi) for c, (lo, hi) in zip(commanded, self._bounds,
                                                                 strict=True)]
        self.saturated = clipped != commanded
        tau = np.array(clipped) if self.saturated else command
        acting = u + (tau - command) if self.saturated else u
        if self.input_delay:
            self._acting.append(acting)
            acting = self._acting.popleft()
        self.observer.predict(acting)
        self.u, self.tau_command, self.tau = u, command, tau
        self.step_ns = clock() - start
        return tau
