"""The plant's one table of physical quantities (``[plant]``), each hardware effect an option.

Every effect between the controller's torque and the arm (:mod:`rhmpc.sim.plant.hardware`) is
off at its neutral value; with all of them off the plant is the ideal arm
(:mod:`rhmpc.sim.plant.arm`). The values of Tuna et al.'s PHANToM rig, each with its source, are
the ``hardware`` preset (:data:`rhmpc.experiment.presets.HARDWARE_PLANT`).

The integration: explicit midpoint steps of h = Ts / n. The friction's ``tanh(ω / v_s)`` is a
viscous law of slope F_s / v_s near rest, on an inertia J, so the step must keep h λ, λ = F_s /
(J v_s), inside the method's real stability interval [−2, 0]::

    n ≥ ⌈Ts F_s / (2 J v_s)⌉                      (the stability bound)
    n = max(2, ⌈Ts F_s / (J v_s)⌉)                 (substeps = 0: automatic, a factor 2 inside)

J is each motor's inertia on its output coordinate at home, the other motors held (the diagonal
of S⁻ᵀ M(q0) S⁻¹), or with cables the rotor alone (J_r, on its own friction); the least J v_s /
F_s of the motors sets the bound. Two steps is the least: the ideal arm's accuracy (a local error
per tick below 0.5 µm at the end-effector against a fine RK4, ``tests/sim/plant/test_plant.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

KINDS = ("arm", "linear")
ERRORS_FROM = ("true", "encoders")
#: The fields that switch an effect on away from their neutral (ideal) value.
EFFECTS = ("delay_ticks", "torque_constant", "current_time_constant", "dac_bits",
           "stiction_ratio", "cable_resonance", "error_from")


@dataclass(frozen=True)
class PlantSettings:
    """The plant: its kind, its integration and each hardware effect (off at its neutral value).

    Attributes
    ----------
    kind : str
        ``"arm"``: the nonlinear arm with whatever effects are on (none: the ideal arm, the
        torque applied as commanded); ``"linear"``: the MPC's own linear model as the plant
        (Tuna et al.'s Table I simulation, the effects ignored).
    substeps : int
        Explicit-midpoint steps per control tick [-] (the step h = Ts / substeps); 0:
        automatic (the module's rule). 2: the ideal arm's accuracy count. A count below the
        friction's stability bound is refused.
    friction_smoothing : float
        v_s of the friction's ``tanh(ω / v_s)`` on the motors' output rates [rad/s]: ``5e-3``.
        A smaller v_s makes the friction a steeper viscous law near rest (a residual torque
        below the stiction peak creeps at ≈ v_s τ / F_s) and needs more substeps.
    delay_ticks : int
        I/O delay d [ticks]: the torque computed at tick i reaches the drive at tick i + d and
        acts over the tick after it. 0: none (it acts over the tick after i).
    torque_constant : float
        K_t of the motors [N·m/A]; > 0 makes the drive a current drive: the current command
        i* = S⁻ᵀ τ / (η K_t) through the DAC and the amplifier, the torque η K_t i, clipped at
        ±``dac_range``. 0: the torque is applied as commanded (clipped to the robot's limits).
    dac_range : float
        I_max, the current at the DAC's full scale [A] (with ``torque_constant``; 0 without).
    dac_bits : int
        DAC resolution [bits]: the command rounded to 2 I_max / 2^bits. 0: no quantisation.
    current_time_constant : float
        τ_e of the current-mode amplifier [s]: i̇ = (i* − i) / τ_e. 0: the current is the
        command.
    stiction_ratio : float
        F_s / F_c, the static friction's peak over the Coulomb level [-]. 1: no peak.
    stribeck_velocity : float
        v_S, the output rate over which the stiction peak decays [rad/s] (with a peak).
    cable_resonance : float
        f_r of the cable transmissions [Hz]: each rotor drives its output through a spring and
        a damper (a two-mass model). 0: rigid cables.
    cable_damping_ratio : float
        ζ of each cable [-] (with cables).
    error_from : str
        Which joint angles the loop scores the tip from: ``"true"`` (the arm's) or
        ``"encoders"`` (the forward kinematics of the encoders' angles).
    """

    kind: str = "arm"
    substeps: int = 2
    friction_smoothing: float = 5e-3
    delay_ticks: int = 0
    torque_constant: float = 0.0
    dac_range: float = 0.0
    dac_bits: int = 0
    current_time_constant: float = 0.0
    stiction_ratio: float = 1.0
    stribeck_velocity: float = 0.01
    cable_resonance: float = 0.0
    cable_damping_ratio: float = 0.05
    error_from: str = "true"

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"unknown plant kind {self.kind!r}; valid: {', '.join(KINDS)}")
        if self.error_from not in ERRORS_FROM:
            raise ValueError(f"plant error_from must be one of {', '.join(ERRORS_FROM)}, "
                             f"got {self.error_from!r}")
        _check_numbers(self)
        if (self.torque_constant > 0) != (self.dac_range > 0):
            raise ValueError("plant torque_constant and dac_range go together: both > 0 (a "
                             "current drive) or both 0 (the torque applied as commanded)")
        for name in ("dac_bits", "current_time_constant"):
            if getattr(self, name) and not self.torque_constant:
                raise ValueError(f"plant {name} needs a current drive (plant.torque_constant "
                                 f"and plant.dac_range > 0)")

    @property
    def effects(self) -> tuple[str, ...]:
        """The effects that are on (away from their neutral value), in :data:`EFFECTS` order."""
        neutral = PlantSettings()
        return tuple(name for name in EFFECTS if getattr(self, name) != getattr(neutral, name))

    @property
    def label(self) -> str:
        """``"linear"``, ``"ideal"`` (the arm, no effect on) or ``"hardware"`` (some on)."""
        if self.kind == "linear":
            return "linear"
        return "hardware" if self.effects else "ideal"


def _check_numbers(s: PlantSettings) -> None:
    """Counts are integers ≥ 0 (``substeps`` too: 0 is automatic), quantities finite and ≥ 0,
    the smoothing and the Stribeck velocity > 0 and the stiction ratio ≥ 1."""
    for name in ("substeps", "delay_ticks", "dac_bits"):
        value = getattr(s, name)
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise ValueError(f"plant {name} must be an integer >= 0, got {value!r}")
    for f in fields(s):
        value = getattr(s, f.name)
        if f.type == "float" and not (math.isfinite(value) and value >= 0):
            raise ValueError(f"plant {f.name} must be finite and >= 0, got {value!r}")
    for name in ("friction_smoothing", "stribeck_velocity"):
        if not getattr(s, name) > 0:
            raise ValueError(f"plant {name} must be > 0 [rad/s], got {getattr(s, name)!r}")
    if not s.stiction_ratio >= 1:
        raise ValueError(f"plant stiction_ratio must be >= 1, got {s.stiction_ratio!r}")


def friction_step(settings: PlantSettings, inertia: np.ndarray, coulomb: np.ndarray) -> float:
    """h_f = min_k J_k v_s / F_s,k [s], F_s = ``stiction_ratio`` · F_c (inf without friction).

    Parameters
    ----------
    inertia : (n,)
        J of each motor's coordinate [kg·m²] (module docstring).
    coulomb : (n,)
        F_c of each motor [N·m].
    """
    peak = settings.stiction_ratio * np.broadcast_to(coulomb, np.shape(inertia))
    with np.errstate(divide="ignore"):
        return float(np.min(np.where(peak > 0, inertia * settings.friction_smoothing / peak,
                                     np.inf)))


def integration_steps(settings: PlantSettings, Ts: float, inertia: np.ndarray,
                      coulomb: np.ndarray) -> int:
    """The substeps per tick: ``settings.substeps``, or with 0 the automatic count
    max(2, ⌈Ts / h_f⌉) (:func:`friction_step`).

    Raises
    ------
    ValueError
        An explicit count below the stability bound ⌈Ts / (2 h_f)⌉, naming the automatic one.
    """
    h = friction_step(settings, inertia, coulomb)
    automatic = max(2, math.ceil(Ts / h)) if math.isfinite(h) else 2
    if not settings.substeps:
        return automatic
    if math.isfinite(h) and settings.substeps < math.ceil(Ts / (2 * h)):
        bound = math.ceil(Ts / (2 * h))
        raise ValueError(f"plant substeps = {settings.substeps} is below the friction's "
                         f"stability bound ({bound} for h ≤ 2 J v_s / F_s); set plant.substeps "
                         f">= {bound}, or 0 (automatic: {automatic})")
    return settings.substeps
