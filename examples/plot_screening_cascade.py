"""
The screening cascade, tick by tick
===================================

Every tick the controller first tries to settle its QP without the solver: level 1 takes the
unconstrained minimiser when it satisfies every row; level 2 solves the torque-box QP exactly by
active set; only what is left goes to OSQP (level 3). The reference below is heart-like and jumps
by 2 mm every 250 ms, so that the torque bounds bind after each jump (this is the trajectory of
``rhmpc bench``, shorter).
"""

import matplotlib.pyplot as plt
import numpy as np

from rhmpc.bench.ticks import bench_controller, heart_like_reference
from rhmpc.control.settings import MPCSettings
from rhmpc.robots import linearize, load_robot

arm = linearize(load_robot("phantom"))
controller = bench_controller(arm, MPCSettings())  # the controller's library: its MPC alone
mpc = controller.mpc
ticks = 2000
ref = heart_like_reference(ticks + mpc.N + 1, arm.Ts, np.random.default_rng(0), arm.y0,
                           jump=2e-3, jump_every=500)
x = np.zeros(arm.nx)
level, tau = np.zeros(ticks, int), np.zeros((ticks, mpc.nu))
for k in range(ticks):
    tau[k] = controller.mpc_step(x, ref[k + 1 : k + 1 + mpc.N])
    level[k] = controller.stats.level
    x = arm.A @ x + arm.B @ tau[k]
print({lv: int(np.sum(level == lv)) for lv in (1, 2, 3)})

# %%
# The torque relative to its bound, and the level that settled each tick.
t = 1e3 * arm.Ts * np.arange(ticks)
u_max = mpc.u_max
fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(8, 5), sharex=True, constrained_layout=True,
                               gridspec_kw={"height_ratios": [3, 1]})
for j in range(mpc.nu):
    ax0.plot(t, tau[:, j] / u_max[j], lw=0.8, label=f"joint {j + 1}")
ax0.set(ylabel="τ / τ_max", title="MPC torque, normalised by its bound")
ax0.legend(ncol=3, fontsize=8)
ax1.step(t, level, where="post", color="k", lw=0.8)
ax1.set(xlabel="time [ms]", ylabel="level", yticks=[1, 2, 3])
plt.show()
