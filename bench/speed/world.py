"""World-step throughput: the full link-trust step, fused and composed from the batch kernels.

Rows (``impl``), Scale6-v0 (6 UAVs, 13 channels each), uniform trust:

* ``world`` — ``LinkTrustCore.step``: truth, sensors, faults, the trust-weighted CEKF
  update, prediction and features in one kernel call per step (``envs/world/core_kernel.py``).
* ``world-unfused`` — the same step composed from the separate batch kernels
  (``World.sense``, ``cekf_update``, ``cekf_predict``, ``channel_features``) with NumPy
  copies in between: the core's path before the fused kernel (``UnfusedCore``; same
  numbers, ``tests/test_world_kernel.py`` holds the two equal).
* ``world-v2`` — ``LinkTrustCore.step`` on the v2 backbone: Scale6-v1 with its peers fused by
  split covariance intersection in the step kernel (``FilterSettings.peer_update = "split_ci"``).
  The world's draws are still v1's.
* ``world-sense`` — ``World.sense`` alone on Scale6-v0 (truth, IMU, channels and faults, no filter): the
  ceiling of every row above, whose draws it makes (mostly the Box–Muller normals, frozen with the
  tasks that shipped results on them).

Only steps are timed, not resets; each figure is the best of a few repeats (the machine
may be shared). ``env_steps_per_s`` counts episodes × steps per second,
``uav_steps_per_s`` UAVs × steps.
"""

from __future__ import annotations

import time

import numpy as np

from swarmloc.bench.speed.kernels import BATCHES, QUICK_BATCHES
from swarmloc.envs.filter import cekf
from swarmloc.envs.world.core import LinkTrustCore
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.tasks.catalogue import get_spec
from swarmloc.envs.world.sim import World

TASK = "swarmloc/Scale6-v0"
#: the ``world-v2`` row: the Scale6 geometry on the v2 backbone
V2_TASK, V2_OVERRIDES = "swarmloc/Scale6-v1", {"filter": {"peer_update": "split_ci"}}


class UnfusedCore:
    """The link-trust step composed from the separate batch kernels, as the core ran it before.

    Same protocol and numbers as ``LinkTrustCore`` on a simulated world, for episodes that
    start together and are stepped together (no partial reset, no finished episode):
    ``reset(seeds)``, then ``step(trust)`` returns the core's outputs by name.

    Args:
        spec: a simulated task.
        batch_size: B.
    """

    def __init__(self, spec: TaskSpec, batch_size: int):
        self.spec = spec
        self.world = World(spec, batch_size)
        lay = self.world.layout
        n_b, n, n_l = batch_size, spec.n_uav, lay.n_channels
        self.x, self.P = np.zeros((n_b, n, 6)), np.zeros((n_b, n, 6, 6))
        self.peer_update = cekf.PEER_UPDATE_CODES[spec.filter.peer_update]
        self.P_ind = np.zeros_like(self.P) if spec.filter.peer_update == "split_ci" else None
        self.split_w = np.zeros((n_b, n, n_l + 1)) if spec.filter.peer_update == "split_ci" else None
        self.prior_pos, self.r0 = np.zeros((n_b, n, 3)), np.ascontiguousarray(lay.r0)
        self.z, self.valid = np.zeros((n_b, n, n_l, 3)), np.zeros((n_b, n, n_l), dtype=bool)
        self.out = {name: np.zeros((n_b, n, n_l)) for name in ("resid", "pred", "nis", "applied", "prev_trust")}
        self.out.update({name: np.zeros((n_b, n, n_l), dtype=bool)
                         for name in ("valid", "update_valid", "label", "active")})
        self.out.update(jerk=np.zeros((n_b, n)), flops=np.zeros((n_b, n)), estimate=np.zeros((n_b, n, 3)),
                        truth=np.zeros((n_b, n, 3)), steps=np.zeros(n_b, dtype=np.int64))

    def reset(self, seeds: np.ndarray) -> dict[str, np.ndarray]:
        """Start every episode; returns the first pending features."""
        f, o = self.spec.filter, self.out
        self.x[:] = self.world.reset(seeds)
        self.P[:] = cekf.initial_covariance(len(seeds), self.spec.n_uav, f.init_pos_sigma, f.init_vel_sigma)
        if self.P_ind is not None:
            self.P_ind[:] = self.P
            self.split_w[:] = 0.0
        o["estimate"][:] = self.x[:, :, :3]
        o["truth"][:] = self.world.buffers.pos
        o["applied"][:] = o["prev_trust"][:] = 1.0
        o["label"][:] = o["update_valid"][:] = o["active"][:] = False
        o["flops"][:] = 0.0
        o["steps"][:] = 0
        self._advance()
        return o

    def step(self, trust: np.ndarray) -> dict[str, np.ndarray]:
        """Apply ``trust`` ``(B, N, L)`` to the pending update, then sense and predict the next step."""
        w, s, lay, o = self.world, self.spec, self.world.layout, self.out
        cekf.cekf_update(self.x, self.P, self.z, self.valid, trust, lay.kind, lay.target, self.r0, w.anchors,
                         w.landmarks, self.prior_pos, s.filter.alpha_th, s.filter.alpha_min, o["active"], o["flops"],
                         self.peer_update, self.P_ind, self.split_w)
        o["estimate"][:] = self.x[:, :, :3]
        o["truth"][:] = w.buffers.pos
        o["label"][:] = w.buffers.label
        o["update_valid"][:] = self.valid
        o["prev_trust"][:] = o["applied"]
        o["applied"][:] = trust
        o["steps"] += 1
        self._advance()
        return o

    def _advance(self) -> None:
        w, s, lay, o = self.world, self.spec, self.world.layout, self.out
        prev_imu = w.buffers.imu.copy()
        buf = w.sense()
        cekf.cekf_predict(self.x, self.P, buf.imu, s.dt, s.sensors.imu_sigma, self.prior_pos, self.P_ind)
        self.z[:] = buf.z
        self.valid[:] = buf.valid
        cekf.channel_features(self.x, self.P, self.z, self.valid, lay.kind, lay.target, self.r0, w.anchors,
                              w.landmarks, self.prior_pos, s.peer_nis_neighbour_cov, o["resid"], o["pred"], o["nis"])
        o["jerk"][:] = np.linalg.norm(buf.imu - prev_imu, axis=-1)
        o["valid"][:] = self.valid


def time_steps(core: LinkTrustCore | UnfusedCore | World, batch: int, n_steps: int, repeats: int) -> float:
    """Best seconds over ``repeats`` for ``n_steps`` steps from a fresh reset (the reset is not timed): a core's
    ``step`` with full trust, or a world's ``sense``."""
    if isinstance(core, World):
        step = core.sense
    else:
        trust = np.ones((batch, core.spec.n_uav, core.spec.n_channels))

        def step() -> None:
            core.step(trust)
    core.reset(np.arange(batch))
    step()  # compile / load the kernels
    best = float("inf")
    for _ in range(repeats):
        core.reset(np.arange(batch))
        t0 = time.perf_counter()
        for _ in range(n_steps):
            step()
        best = min(best, time.perf_counter() - t0)
    return best


def measure_rows(quick: bool = False) -> list[dict]:
    """The ``world``, ``world-unfused``, ``world-v2`` and ``world-sense`` rows at every batch size (``quick``:
    ``QUICK_BATCHES``, short runs)."""
    spec, v2 = get_spec(TASK), get_spec(V2_TASK, **V2_OVERRIDES)
    rows = []
    for batch in QUICK_BATCHES if quick else BATCHES:
        n_steps = 20 if quick else (300 if batch <= 64 else 50)
        repeats = 2 if quick else (5 if batch <= 64 else 3)
        for impl, make, task in (("world", LinkTrustCore, spec), ("world-unfused", UnfusedCore, spec),
                                 ("world-v2", LinkTrustCore, v2)):
            sec = time_steps(make(task, batch), batch, n_steps, repeats)
            rows.append({"impl": impl, "B": batch, "env_steps_per_s": batch * n_steps / sec,
                         "uav_steps_per_s": batch * spec.n_uav * n_steps / sec})
        sec = time_steps(World(spec, batch), batch, n_steps, repeats)
        rows.append({"impl": "world-sense", "B": batch, "env_steps_per_s": batch * n_steps / sec,
                     "uav_steps_per_s": batch * spec.n_uav * n_steps / sec})
    return rows
