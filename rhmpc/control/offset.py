"""Output offset of the linearised arm, measured each tick by forward kinematics.

The MPC's output model is linear about the home posture, ``y = C x + y0``. Offset-free MPC
(Muske & Badgwell, J. Process Control 12(5), 2002; Pannocchia & Rawlings, AIChE J. 49(2), 2003)
adds a disturbance ``d`` to the output, ``y_k = C x_k + y0 + d``, held constant over the horizon.
Here the disturbance is not estimated from measurements of ``y`` but computed exactly from the
estimated joint state, since the output is a known function of it::

    d = p(q0 + x̂_q) − (C x̂ + y0)

so the predicted output starts on the true forward kinematics every tick. What is left is the
change of the Jacobian over the horizon's motion (second order in the planned motion).

The forward kinematics are Pinocchio's. The controller writes x into its parameter vector
anyway; :meth:`OutputOffset.evaluate` reads it there (the ``state`` array), which saves the copy.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin


class OutputOffset:
    """``d(x̂) = p(q0 + x̂_q) − (C x̂ + y0)`` [m], one forward-kinematics call per evaluation.

    Parameters
    ----------
    arm : rhmpc.robots.LinearArm
        The linearised arm; ``arm.robot`` gives the forward kinematics.
    out : ndarray (3,), optional
        Where every evaluation writes d (e.g. a controller's parameter slot); default its own.
    state : ndarray (2nv,), optional
        Where x is read: :meth:`__call__` writes its x there, :meth:`evaluate` reads what the
        caller wrote (e.g. the state slot of the same parameter vector); default its own.

    Raises
    ------
    ValueError
        If the arm does not carry its robot (``rhmpc.robots.linearize`` keeps it).
    """

    def __init__(self, arm, out: np.ndarray | None = None,
                 state: np.ndarray | None = None) -> None:
        robot = getattr(arm, "robot", None)
        if robot is None:
            raise ValueError(
                "offset_correction needs the arm's robot for forward kinematics "
                "(rhmpc.robots.linearize(robot) keeps it); set offset_correction = false otherwise"
            )
        self._model = robot.model
        self._data = robot.create_data()  # our own work data: no sharing with other users
        self._fid = robot.ee_frame_id
        nq = arm.nx // 2
        self._q0 = np.asarray(arm.q0, dtype=float).copy()
        self._q = np.empty(nq)
        self._nq = nq
        self._C = np.ascontiguousarray(arm.C)
        self._y0 = np.asarray(arm.y0, dtype=float).copy()
        self._y = np.empty(3)
        #: where every evaluation writes d (3,) [m]
        self.out = np.zeros(3) if out is None else out
        #: where :meth:`evaluate` reads x (2nv,): the caller's copy of the state
        self.state = np.zeros(2 * nq) if state is None else state

    def __call__(self, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """The offset d (3,) [m] at the state ``x`` = [q − q0; q̇], written into :attr:`state`
        first: in :attr:`out`, and copied to ``out`` if another array is given."""
        self.state[:] = x
        self.evaluate()
        if out is None or out is self.out:
            return self.out
        out[:] = self.out
        return out

    def evaluate(self) -> np.ndarray:
        """The offset at the x the caller wrote into :attr:`state`, in :attr:`out` (the array)."""
        x = self.state
        q = np.add(self._q0, x[: self._nq], out=self._q)
        pin.forwardKinematics(self._model, self._data, q)
        p = pin.updateFramePlacement(self._model, self._data, self._fid).translation
        lin = np.dot(self._C, x, out=self._y)
        lin += self._y0
        return np.subtract(p, lin, out=self.out)
