"""The plants' equations written plainly on Pinocchio: the references the kernel is checked against.

Nothing here is fast or shared with the package: each equation of ``sim/plant/chain.c`` is
restated from the docstrings of :mod:`rhmpc.sim.plant.arm` and :mod:`rhmpc.sim.plant.hardware`, with
Pinocchio's M(q) (``pin.crba``) and h(q, q̇) (``pin.nonLinearEffects``).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin


def friction(w, coulomb, damping, ratio, v_stribeck, v_smooth):
    """f(ω) = D ω + [F_c + (F_s − F_c) exp(−(ω/v_S)²)] tanh(ω/v_s), F_s = ratio·F_c [N·m]."""
    peak = coulomb * (1.0 + (ratio - 1.0) * np.exp(-np.square(w / v_stribeck)))
    return damping * w + peak * np.tanh(w / v_smooth)


def mass_and_bias(robot, data, q, v):
    """M(q) (both triangles, with the armature) and h(q, q̇) from Pinocchio."""
    M = pin.crba(robot.model, data, q)
    return np.triu(M) + np.triu(M, 1).T, pin.nonLinearEffects(robot.model, data, q, v)


def ideal_rates(robot, data, q, v, tau, v_s):
    """q̈ of the ideal plant: M q̈ + h = τ − Sᵀ(D S q̇ + F_c tanh(S q̇ / v_s))."""
    S = robot.motor_map
    f = S.T @ friction(S @ v, robot.coulomb_friction, robot.damping, 1.0, 1.0, v_s)
    M, h = mass_and_bias(robot, data, q, v)
    return np.linalg.solve(M, tau - f - h)


def ideal_tick(robot, q, v, tau, Ts, substeps=2, v_s=5e-3):
    """One tick of the ideal plant: τ clipped to the torque limits, explicit midpoint steps."""
    data, h = robot.create_data(), Ts / substeps
    tau = np.clip(tau, -robot.torque_limit, robot.torque_limit)
    for _ in range(substeps):
        a = ideal_rates(robot, data, q, v, tau, v_s)
        q_mid, v_mid = q + 0.5 * h * v, v + 0.5 * h * a
        q, v = q + h * v_mid, v + h * ideal_rates(robot, data, q_mid, v_mid, tau, v_s)
    return q, v


def hardware_tick(robot, settings, state, current, tau, Ts=0.5e-3, steps=None):
    """One tick of the hardware-like plant after its delay, from ``state`` = [q, q̇, θ_r, θ̇_r]
    and the winding currents: the DAC, the lag (the current's exact mean over each step), the
    rigid or cable dynamics, ``steps`` explicit midpoint steps (default ``settings.substeps``).
    Returns the new state and currents."""
    S, q0, n = robot.motor_map, robot.q0, robot.nv
    gain = robot.gear_ratio * settings.torque_constant
    wanted = np.linalg.solve(S.T, tau) / gain
    if settings.dac_bits:
        step = 2 * settings.dac_range / 2**settings.dac_bits
        wanted = step * np.round(wanted / step)
    command = np.clip(wanted, -settings.dac_range, settings.dac_range)
    data, steps = robot.create_data(), steps or settings.substeps
    h, tau_e = Ts / steps, settings.current_time_constant
    rotor, (k, c) = robot.rotor_inertia, cables_of(robot, settings)

    def f(w):
        return friction(w, robot.coulomb_friction, robot.damping, settings.stiction_ratio,
                        settings.stribeck_velocity, settings.friction_smoothing)

    def rates(x, i):
        q, v, th, om = np.split(x, 4)
        M, bias = mass_and_bias(robot, data, q, v)
        if settings.cable_resonance > 0:
            spring = k * (th - S @ (q - q0)) + c * (om - S @ v)
            M = M - S.T @ np.diag(rotor) @ S
            return np.r_[v, np.linalg.solve(M, S.T @ spring - bias), om,
                         (gain * i - spring - f(om)) / rotor]
        return np.r_[v, np.linalg.solve(M, S.T @ (gain * i - f(S @ v)) - bias), np.zeros(2 * n)]

    x = np.concatenate(state)
    for s in range(steps):
        if tau_e > 0:
            t = s * h
            i = command + (current - command) * tau_e / h * (math.exp(-t / tau_e)
                                                            - math.exp(-(t + h) / tau_e))
        else:
            i = command
        x = x + h * rates(x + 0.5 * h * rates(x, i), i)
    if tau_e > 0:
        current = command + (current - command) * math.exp(-steps * h / tau_e)
    else:
        current = command
    return np.split(x, 4), current


def cables_of(robot, settings):
    """(k, c) of the cables from their resonance: k = (2π f_r)² J_r J_l/(J_r + J_l), J_l the
    links' inertia on each motor's coordinate at home, c = 2ζ√(k J_r J_l/(J_r + J_l))."""
    if settings.cable_resonance <= 0:
        return np.zeros(robot.nv), np.zeros(robot.nv)
    S, rotor = robot.motor_map, robot.rotor_inertia
    M_l = robot.mass_matrix(robot.q0) - S.T @ np.diag(rotor) @ S
    S_inv = np.linalg.inv(S)
    link = np.diag(S_inv.T @ M_l @ S_inv)
    reduced = rotor * link / (rotor + link)
    k = (2 * math.pi * settings.cable_resonance) ** 2 * reduced
    return k, 2 * settings.cable_damping_ratio * np.sqrt(k * reduced)
