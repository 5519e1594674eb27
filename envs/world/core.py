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

from dataclasses import dataclass

import numpy as np

from swarmloc.envs.filter import cekf
from swarmloc.envs.world.core_kernel import FilterArrays, make_handle, step_kernel
from swarmloc.envs.world.labels import label_thresholds
from swarmloc.envs.tasks.specs import TaskSpec
from swarmloc.envs.world.sim import World
from swarmloc.envs.world.sim_kernel import SERIAL_BELOW  # noqa: F401  (the speed benchmark runs small batches as the core does)
from swarmloc.envs.world.worlds import AnyWorld, make_world


@dataclass
class CoreStep:
    """What one ``reset``/``step`` returns (arrays are views into the core's buffers).

    Attributes:
        resid: ``(B, N, L)`` innovation magnitude ‖y‖ of the pending measurements [m].
        pred: ``(B, N, L)`` predicted distance ‖h(x⁻)‖ [m].
        nis: ``(B, N, L)`` normalised innovation squared with nominal R0 (v1 tasks: a peer
            channel's S includes the neighbour's broadcast covariance, ``cekf.channel_features``).
        prev_trust: ``(B, N, L)`` trust applied at the previous update.
        jerk: ``(B, N)`` IMU jerk ‖u(k) − u(k−1)‖ [m/s²].
        valid: ``(B, N, L)`` pending measurement present.
        update_valid: ``(B, N, L)`` measurement present in the last update (what its reward scores).
        estimate: ``(B, N, 3)`` posterior position of the last update (prior mean after reset).
        truth: ``(B, N, 3)`` true position at the last update.
        label: ``(B, N, L)`` injected-fault labels (``SenseBuffers.label``) of the measurements of the last update.
        error_label: ``(B, N, L)`` their error labels (``labels.py``: systematic error, peer links
            included through the neighbour's broadcast estimate, above k·σ_eff).
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
    update_valid: np.ndarray
    estimate: np.ndarray
    truth: np.ndarray
    label: np.ndarray
    error_label: np.ndarray
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
        #: ``(B, N, 6, 6)`` the independent part of P under ``peer_update = "split_ci"`` (``cekf``'s
        #: ``split_ci.py``); ``(0, 0, 6, 6)`` under the other updates
        split = spec.filter.peer_update == "split_ci"
        self.P_ind = np.zeros((n_b, n, 6, 6) if split else (0, 0, 6, 6))
        #: ``(B, N, L + 1)`` under ``"split_ci"``: the weights of every UAV's previous peer update, where the next
        #: one's search starts (zeros: cold); ``(0, 0, 1)`` under the other updates
        self.split_w = np.zeros((n_b, n, n_l + 1) if split else (0, 0, 1))
        self._prior_pos = np.zeros((n_b, n, 3))
        self._r0 = np.ascontiguousarray(self.layout.r0)
        #: ``(N, L)`` error-label threshold per channel (the world's, so that its own-error labels
        #: and the core's agree)
        threshold = getattr(world, "label_threshold", None)
        self.label_threshold = np.ascontiguousarray(label_thresholds(self.layout.kind) if threshold is None
                                                    else threshold, dtype=np.float64)
        #: ``(B, N, L)`` privileged: the pending measurements' systematic error in units of σ_eff
        #: and their error labels (``labels.py``); metrics and ``observe_privileged`` only
        self.pending_systematic_sigmas = np.zeros((n_b, n, n_l))
        self.pending_error_label = np.zeros((n_b, n, n_l), dtype=np.bool_)
        z = lambda *shape, dt=np.float64: np.zeros(shape, dtype=dt)  # noqa: E731
        self._out = CoreStep(
            resid=z(n_b, n, n_l), pred=z(n_b, n, n_l), nis=z(n_b, n, n_l), prev_trust=np.ones((n_b, n, n_l)),
            jerk=z(n_b, n), valid=z(n_b, n, n_l, dt=np.bool_), update_valid=z(n_b, n, n_l, dt=np.bool_),
            estimate=z(n_b, n, 3), truth=z(n_b, n, 3),
            label=z(n_b, n, n_l, dt=np.bool_), error_label=z(n_b, n, n_l, dt=np.bool_), applied=np.ones((n_b, n, n_l)),
            active=z(n_b, n, n_l, dt=np.bool_), flops=z(n_b, n), steps=z(n_b, dt=np.int64),
            done=z(n_b, dt=np.bool_),
        )
        self._init_kernel()

    # ------------------------------------------------------------------ internals
    def _init_kernel(self) -> None:
        """Bind the step kernel to the core's and the world's arrays (``core_kernel.step_kernel``)."""
        w, s, o, buf = self.world, self.spec, self._out, self.world.buffers
        self._filter = FilterArrays(
            dt=float(s.dt), imu_sigma=float(s.sensors.imu_sigma), alpha_th=float(s.filter.alpha_th),
            alpha_min=float(s.filter.alpha_min), n_steps=int(s.n_steps), peer_cov=bool(s.peer_nis_neighbour_cov),
            peer_update=cekf.PEER_UPDATE_CODES[s.filter.peer_update],
            kind=self.layout.kind,
            target=self.layout.target, r0=self._r0, sigma=np.ascontiguousarray(self.layout.sigma),
            label_threshold=self.label_threshold, anchors=w.anchors, landmarks=w.landmarks, world_pos=buf.pos,
            world_imu=buf.imu, world_z=buf.z, world_valid=buf.valid, world_label=buf.label,
            world_systematic=buf.systematic, x=self.x, P=self.P, P_ind=self.P_ind, split_w=self.split_w,
            prior_pos=self._prior_pos,
            imu_prev=np.zeros_like(buf.imu), pending_sigmas=self.pending_systematic_sigmas,
            pending_error_label=self.pending_error_label, resid=o.resid, pred=o.pred, nis=o.nis,
            valid=o.valid, jerk=o.jerk, estimate=o.estimate, truth=o.truth, label=o.label, error_label=o.error_label,
            update_valid=o.update_valid, applied=o.applied, prev_trust=o.prev_trust, active=o.active, flops=o.flops,
            steps=o.steps, done=o.done, moving=np.zeros(self.batch_size, dtype=bool),
        )
        # a simulated world senses inside the kernel; any other world senses in Python first
        self._senses = isinstance(w, World)
        world_arrays = (w.inputs, w.schedule) if self._senses else (None, None)
        self._handle = make_handle(*world_arrays, self._filter)
        self._step = step_kernel(self.batch_size)
        self._everyone = np.ones(self.batch_size, dtype=bool)

    def _advance(self, mask: np.ndarray | None = None, trust: np.ndarray | None = None) -> None:
        """Score the pending update with ``trust`` (if given), then sense and predict the next step.

        The episodes that go on are those not done, within ``mask`` when given (a partial
        reset); the others do not move. A simulated world does it all in one kernel call.
        """
        go = self._everyone if mask is None else mask
        score = trust is not None
        if self._senses:
            self._step(self._handle, trust if score else self._out.applied, score, go)
            return
        w, f = self.world, self._filter
        if score:
            self._step(self._handle, trust, True, ~self._everyone)
            go = go & ~f.done
        keep = ~go
        saved = [a[keep].copy() for a in self._world_state()] if keep.any() else []
        f.imu_prev[:] = w.buffers.imu
        w.sense()
        for array, value in zip(self._world_state(), saved):
            array[keep] = value
        self._step(self._handle, self._out.applied, False, go)

    # ------------------------------------------------------------------ API
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
        if len(self.P_ind):  # "split_ci": the initial errors are drawn independently, P0 is all independent
            self.P_ind[idx] = self.P[idx]
            self.split_w[idx] = 0.0  # the first peer update's weight search starts cold
        o.estimate[idx] = self.x[idx, :, :3]
        o.truth[idx] = w.buffers.pos[idx]
        o.prev_trust[idx] = 1.0
        o.applied[idx] = 1.0
        o.label[idx] = False
        o.error_label[idx] = False
        o.update_valid[idx] = False
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
        """Sense and predict the next step of episodes ``idx`` only (a partial reset)."""
        mask = np.zeros(self.batch_size, dtype=bool)
        mask[idx] = True
        self._advance(mask)

    def _world_state(self) -> list[np.ndarray]:
        """The ``(B, ...)`` arrays that one ``sense`` of a world sensing in Python changes (restored
        for the episodes that do not move): its step counter and every step buffer it fills."""
        w = self.world
        # optional buffers such as VO velocity are None when absent
        return [w.steps] + [a for a in vars(w.buffers).values() if isinstance(a, np.ndarray)]

    def step(self, trust: np.ndarray) -> CoreStep:
        """Apply ``trust`` to the pending update and advance.

        The trust is used as given: callers validate it once (``TrustEnvBatch.check`` or an
        adapter's ``ActionChecker``: shape, finite, clipped to [0, 1]).

        Args:
            trust: ``(B, N, L)`` float64 trust α per channel, in [0, 1].

        Returns:
            The ``CoreStep`` (estimates and truth of the update just done; features of the
            next pending update). Episodes already done are not advanced.
        """
        o = self._out
        if o.done.all():
            raise RuntimeError("every episode is done; call reset() first")
        # one kernel call: the update and its outputs (estimate, truth, labels, validity,
        # trust, FLOPs, step count) for the live episodes, then the next pending step of
        # those that are not done (core_kernel.step_kernel). A view (a slice, a transpose) is
        # copied to one contiguous layout: the kernel is compiled for that layout only, and a
        # second layout would cost a second compilation of the whole step (minutes, cold).
        self._advance(trust=np.ascontiguousarray(trust, dtype=np.float64))
        return o
