"""The batched link-trust core: world + CEKF backbone, ``reset(seeds)`` / ``step(trust)``.

Step protocol (Track A). After ``reset`` (or a ``step``) the core holds, for every
episode, the *pending* step k: the world has sensed step k and the CEKF has predicted to
it, so the per-channel innovation features at the prior are known. ``step(trust)``
applies the trust to that pending update (posterior at k), scores it against the truth
at k, then senses and predicts step k+1 and returns its features. An episode is done
after ``spec.n_steps`` updates. Every adapter (Gymnasium, vector, PettingZoo, torchrl)
wraps this class; none holds physics.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numba
import numpy as np

from . import cekf
from .specs import TaskSpec
from .world import World
from .worlds import AnyWorld, make_world

#: private per-episode state of the simulated world that one ``sense`` changes (Gauss–Markov NLOS)
_WORLD_PRIVATE_STATE = ("_gm_bias", "_gm_left")


#: below this batch size the kernels run on the calling thread: a parallel region over a
#: handful of episodes costs more than it saves, and on a busy machine OpenMP workers that
#: spin-wait for their turn can make one step take tens of milliseconds
SERIAL_BELOW = 32


def small_batch_serial(method):
    """Run a core method with one numba thread when the core's batch is small."""

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        threads = numba.get_num_threads()
        if self.batch_size >= SERIAL_BELOW or threads == 1:
            return method(self, *args, **kwargs)
        numba.set_num_threads(1)
        try:
            return method(self, *args, **kwargs)
        finally:
            numba.set_num_threads(threads)

    return wrapper


@dataclass
class CoreStep:
    """What one ``reset``/``step`` returns (arrays are views into the core's buffers).

    Attributes:
        resid: ``(B, N, L)`` innovation magnitude ‖y‖ of the pending measurements [m].
        pred: ``(B, N, L)`` predicted distance ‖h(x⁻)‖ [m].
        nis: ``(B, N, L)`` normalised innovation squared with nominal R0.
        prev_trust: ``(B, N, L)`` trust applied at the previous update.
        jerk: ``(B, N)`` IMU jerk ‖u(k) − u(k−1)‖ [m/s²].
        valid: ``(B, N, L)`` pending measurement present.
        estimate: ``(B, N, 3)`` posterior position of the last update (prior mean after reset).
        truth: ``(B, N, 3)`` true position at the last update.
        label: ``(B, N, L)`` fault labels of the measurements of the last update.
        applied: ``(B, N, L)`` trust applied at the last update (1 after reset).
        active: ``(B, N, L)`` channels used by the last update.
        flops: ``(B, N)`` CEKF FLOPs of the last step.
        steps: ``(B,)`` updates done in the episode.
        done: ``(B,)`` episode finished (``steps == spec.n_steps``).
    """

    resid: np.ndarray
    pred: np.ndarray
    nis: np.ndarray
    prev_trust: np.ndarray
    jerk: np.ndarray
    valid: np.ndarray
    estimate: np.ndarray
    truth: np.ndarray
    label: np.ndarray
    applied: np.ndarray
    active: np.ndarray
    flops: np.ndarray
    steps: np.ndarray
    done: np.ndarray


class LinkTrustCore:
    """B episodes of one task with the CEKF backbone driven by per-channel trust.

    Args:
        spec: the task.
        batch_size: B.
        world: the world to drive (default: ``make_world(spec, batch_size)``, the simulated
            ``World`` or, for a recorded task, the ``RecordedWorld``). Anything with the
            world interface works: ``spec``, ``batch_size``, ``layout``, ``anchors``,
            ``landmarks``, ``buffers``, ``steps``, ``x0``, ``reset(seeds, mask)``, ``sense()``.
    """

    def __init__(self, spec: TaskSpec, batch_size: int, world: World | AnyWorld | None = None):
        self.spec = spec
        if world is None:
            world = make_world(spec, batch_size)
        elif world.batch_size != batch_size or world.spec != spec:
            raise ValueError(f"the injected world runs {world.spec.task_id} with batch size {world.batch_size}; "
                             f"the core was asked for {spec.task_id} with batch size {batch_size}")
        self.world = world
        self.layout = self.world.layout
        n_b, n, n_l = batch_size, spec.n_uav, self.layout.n_channels
        self.batch_size, self.n_uav, self.n_channels = n_b, n, n_l
        self.x = np.zeros((n_b, n, 6))
        self.P = np.zeros((n_b, n, 6, 6))
        self._prior_pos = np.zeros((n_b, n, 3))
        self._r0 = np.ascontiguousarray(self.layout.r0)
        z = lambda *shape, dt=np.float64: np.zeros(shape, dtype=dt)  # noqa: E731
        self._out = CoreStep(
            resid=z(n_b, n, n_l), pred=z(n_b, n, n_l), nis=z(n_b, n, n_l), prev_trust=np.ones((n_b, n, n_l)),
            jerk=z(n_b, n), valid=z(n_b, n, n_l, dt=np.bool_), estimate=z(n_b, n, 3), truth=z(n_b, n, 3),
            label=z(n_b, n, n_l, dt=np.bool_), applied=np.ones((n_b, n, n_l)),
            active=z(n_b, n, n_l, dt=np.bool_), flops=z(n_b, n), steps=z(n_b, dt=np.int64),
            done=z(n_b, dt=np.bool_),
        )
        self._flops = z(n_b, n)
        self._z = z(n_b, n, n_l, 3)
        self._valid = z(n_b, n, n_l, dt=np.bool_)

    # ------------------------------------------------------------------ internals
    def _advance(self, idx: np.ndarray | None = None) -> None:
        """Sense the next step and predict to it (pending update), for all episodes."""
        w, s = self.world, self.spec
        prev_imu = w.buffers.imu.copy()
        buf = w.sense()
        cekf.cekf_predict(self.x, self.P, buf.imu, s.dt, s.sensors.imu_sigma, self._prior_pos)
        self._z[:] = buf.z
        self._valid[:] = buf.valid
        o = self._out
        cekf.channel_features(self.x, self.P, self._z, self._valid, self.layout.kind, self.layout.target,
                              self._r0, w.anchors, w.landmarks, self._prior_pos, o.resid, o.pred, o.nis)
        o.jerk[:] = np.linalg.norm(buf.imu - prev_imu, axis=-1)
        o.valid[:] = self._valid

    # ------------------------------------------------------------------ API
    @small_batch_serial
    def reset(self, seeds: np.ndarray | list[int], mask: np.ndarray | None = None) -> CoreStep:
        """Start (some) episodes and return their first pending features.

        Args:
            seeds: ``(B,)`` non-negative seeds.
            mask: optional ``(B,)`` bool; reset only these episodes. Episodes outside the
                mask are not advanced.
        """
        idx = np.arange(self.batch_size) if mask is None else np.nonzero(np.asarray(mask, bool))[0]
        w, f, o = self.world, self.spec.filter, self._out
        w.reset(seeds, mask)
        self.x[idx] = w.x0[idx]
        self.P[idx] = cekf.initial_covariance(len(idx), self.n_uav, f.init_pos_sigma, f.init_vel_sigma)
        o.estimate[idx] = self.x[idx, :, :3]
        o.truth[idx] = w.buffers.pos[idx]
        o.prev_trust[idx] = 1.0
        o.applied[idx] = 1.0
        o.label[idx] = False
        o.active[idx] = False
        o.flops[idx] = 0.0
        o.steps[idx] = 0
        o.done[idx] = False
        if mask is None:
            self._advance()
        else:
            self._advance_subset(idx)
        return o

    def _advance_subset(self, idx: np.ndarray) -> None:
        # Only the reset episodes may move: run the step on a sub-batch and scatter back.
        keep = np.ones(self.batch_size, dtype=bool)
        keep[idx] = False
        saved = {name: getattr(self, name)[keep].copy() for name in ("x", "P", "_prior_pos", "_z", "_valid")}
        world_state = self._world_state()
        saved_world = [a[keep].copy() for a in world_state]
        o = self._out
        saved_out = {name: getattr(o, name)[keep].copy() for name in ("resid", "pred", "nis", "jerk", "valid")}
        self._advance()
        for name, value in saved.items():
            getattr(self, name)[keep] = value
        for array, value in zip(world_state, saved_world):
            array[keep] = value
        for name, value in saved_out.items():
            getattr(o, name)[keep] = value

    def _world_state(self) -> list[np.ndarray]:
        """The world's ``(B, ...)`` arrays that one ``sense`` changes (restored for episodes not advanced)."""
        w = self.world
        # every step buffer the world fills (optional ones such as VO velocity are None when absent)
        arrays = [w.steps] + [a for a in vars(w.buffers).values() if isinstance(a, np.ndarray)]
        return arrays + [getattr(w, name) for name in _WORLD_PRIVATE_STATE if hasattr(w, name)]

    def check_trust(self, trust: np.ndarray) -> np.ndarray:
        """Validate a trust array: shape ``(B, N, L)``, finite; returns it as float64."""
        trust = np.asarray(trust, dtype=np.float64)
        expected = (self.batch_size, self.n_uav, self.n_channels)
        if trust.shape != expected:
            raise ValueError(f"trust must have shape (B, N, L) = {expected}, got {trust.shape}")
        if not np.isfinite(trust).all():
            bad = np.argwhere(~np.isfinite(trust))[0]
            raise ValueError(f"trust must be finite; got {trust[tuple(bad)]} at index {tuple(bad.tolist())}")
        return trust

    @small_batch_serial
    def step(self, trust: np.ndarray) -> CoreStep:
        """Apply ``trust`` (in [0, 1]; clipped) to the pending update and advance.

        Args:
            trust: ``(B, N, L)`` trust α per channel.

        Returns:
            The ``CoreStep`` (estimates and truth of the update just done; features of the
            next pending update). Episodes already done are not advanced.
        """
        trust = np.clip(self.check_trust(trust), 0.0, 1.0)
        o, w, s, lay = self._out, self.world, self.spec, self.layout
        if o.done.all():
            raise RuntimeError("every episode is done; call reset() first")
        cekf.cekf_update(self.x, self.P, self._z, self._valid, trust, lay.kind, lay.target, self._r0,
                         w.anchors, w.landmarks, self._prior_pos, s.filter.alpha_th, s.filter.alpha_min,
                         o.active, self._flops)
        live = slice(None) if not o.done.any() else ~o.done
        o.estimate[live] = self.x[live, :, :3]
        o.truth[live] = w.buffers.pos[live]
        o.label[live] = w.buffers.label[live]
        o.prev_trust[live] = o.applied[live]
        o.applied[live] = trust[live]
        o.flops[live] = self._flops[live]
        o.steps[live] += 1
        o.done[:] = o.steps >= s.n_steps
        if o.done.all():
            return o
        if o.done.any():
            self._advance_subset(np.nonzero(~o.done)[0])
        else:
            self._advance()
        return o
