"""The controller a robot runs: the reference, the observer, the MPC and the cancellation, one
library.

Its tick is the C that ``rhmpc export`` generates from this package's description (the
formulation, the settings, the numbers: :mod:`rhmpc.control.export`); in Python it is
:class:`Controller`, a binding to that library, built once per distinct description::

    controller.refresh(tick, z, stamp)     a sensor sample's arrival: gate → predictor →
                                           interpolation (:mod:`rhmpc.control.reference`)
    controller.forecast(tick, stamp, pts)  or a forecast made outside (another process):
                                           interpolation, in place of the refresh's own
    tau = controller.step(tick, q)         every control tick, from the encoders' angles q̃
    tau = controller.step(tick, q, delay)  or from a reading of tick − delay that came late

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
observer's ``fault_timeout`` (an encoder fault), the MPC brakes instead of tracking (failure
``encoder_fault``). A command that is not finite holds the last torque. A reading that comes
``delay`` ticks late corrects the prior of its own tick, and the observer carries the estimate
to this one with the torques that acted since; q̄ is then the estimate's angles.
"""

from __future__ import annotations

from rhmpc.control.export.binding import Controller

__all__ = ["Controller"]
