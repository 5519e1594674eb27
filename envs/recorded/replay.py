"""A recorded flight behind the world interface: ``RecordedWorld`` replays, it simulates nothing.

``RecordedWorld(spec, B)`` exposes what ``LinkTrustCore`` and the bench runner use of
``swarmloc.envs.world.sim.World`` — ``spec``, ``batch_size``, ``layout``, ``anchors``,
``landmarks``, ``buffers``, ``seeds``, ``steps``, ``x0``, ``times``, ``reset(seeds,
mask)``, ``sense()`` — so the CEKF backbone and every estimator run on real data
unchanged. The spec's trajectory is a ``RecordedFlight`` (which log, where step 0 is,
which calibration); ``util_flight`` holds the rules that turn the log into steps.

* **Anchors** come from the data folder (the flight's anchor file), never from the spec: the data
  set has no licence, so the repository does not embed its survey. The spec holds one
  placeholder per anchor (at the origin) so that the channel layout (L = 8) is known
  without the data; ``world.anchors`` holds the surveyed positions.
* **Determinism.** Every episode replays the same recording. The seed changes only the
  initial prior: truth at step 0 plus N(0, init_pos_sigma²) per position axis and
  N(0, init_vel_sigma²) per velocity axis, drawn from the same counter-based streams as
  the simulated world.
* **Error labels.** On real data the systematic error cannot be told apart from the noise:
  the calibrated residual (range − true distance) stands for it
  (``SenseBuffers.systematic``), and the error labels apply the simulated world's rule to it
  (|residual| / σ above the threshold, k for ranges). The recording's own labels
  (``util_flight``) are its injected-fault labels (``SenseBuffers.label``).
* **No data** → ``FileNotFoundError`` naming the source repository, commits, paths and
  the import command (``find_util_data``).

Batch layout as the simulated world: ``(B, N, ...)`` with N = 1 UAV; channel buffers
``(B, N, L, ...)``; ranges in component 0 of the 3-vector measurement.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from swarmloc.envs.tasks.channels import ChannelLayout, build_layout
from swarmloc.envs.world.labels import label_thresholds
from swarmloc.envs.tasks.rng import Stream, normal
from swarmloc.envs.tasks.specs import RecordedFlight, TaskSpec
from swarmloc.envs.world.sim import SenseBuffers, reset_indices
from swarmloc.envs.recorded.flights import load_flight
from swarmloc.envs.recorded.util_flight import Recording

_INIT = int(Stream.INIT)


class RecordedWorld:
    """B replays of one recorded flight (the world interface, no estimator).

    Args:
        spec: a task whose trajectory is a ``RecordedFlight``.
        batch_size: B.
        data_dir: the folder that contains ``util-twr/`` (default: ``$SWARMLOC_DATA``, else
            ``../shared/data`` beside the checkout; see ``util_import.data_root``).

    Raises:
        ValueError: the spec is not a recorded flight, has several UAVs, landmarks, peers
            or GPS, or its anchor count differs from the survey's; the window does not fit
            in the log.
        FileNotFoundError: the data is missing (the message says where it comes from and
            how to import it).
    """

    def __init__(self, spec: TaskSpec, batch_size: int, data_dir: str | Path | None = None):
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        flight = spec.trajectory
        if not isinstance(flight, RecordedFlight):
            raise ValueError(f"RecordedWorld needs a spec with a recorded trajectory, got {flight.kind!r}")
        if (spec.n_uav != 1 or spec.landmarks or spec.sensors.gps_sigma or spec.n_peer_channels
                or spec.sensors.velocity_sigma is not None):
            raise ValueError(f"{spec.task_id}: a recorded flight has one UAV with anchor channels only; got "
                             f"n_uav={spec.n_uav}, {len(spec.landmarks)} landmarks, "
                             f"{len(spec.sensors.gps_sigma)} GPS, {spec.n_peer_channels} peer channels, "
                             f"VO velocity σ {spec.sensors.velocity_sigma}")
        # the loader of the flight's data set (``flights.py``): TWR ranges or TDOA pairs
        folder, recording = load_flight(spec, data_dir)
        self.recording: Recording = recording
        n_a = len(self.recording.anchors)
        if len(spec.anchors) != n_a:
            raise ValueError(f"{spec.task_id} has {len(spec.anchors)} anchors but {folder / flight.anchors} "
                             f"surveys {n_a} anchors")
        self.spec = spec
        self.batch_size = batch_size
        self.data_folder = folder
        self.layout: ChannelLayout = build_layout(spec)
        self.anchors = np.array(self.recording.anchors)
        self.landmarks = np.zeros((0, 3))
        n_b, n, n_l = batch_size, 1, spec.n_channels
        self.buffers = SenseBuffers(
            pos=np.zeros((n_b, n, 3)), vel=np.zeros((n_b, n, 3)), imu=np.zeros((n_b, n, 3)),
            z=np.zeros((n_b, n, n_l, 3)), valid=np.zeros((n_b, n, n_l), dtype=np.bool_),
            label=np.zeros((n_b, n, n_l), dtype=np.bool_), injected=np.zeros((n_b, n, n_l)),
            error_label=np.zeros((n_b, n, n_l), dtype=np.bool_), systematic=np.zeros((n_b, n, n_l, 3)),
        )
        #: ``(N, L)`` error-label threshold per channel (``labels.label_thresholds``)
        self.label_threshold = label_thresholds(self.layout.kind)
        self.seeds = np.zeros(n_b, dtype=np.int64)
        self.x0 = np.zeros((n_b, n, 6))
        self.steps = np.zeros(n_b, dtype=np.int64)

    @property
    def times(self) -> np.ndarray:
        """``(B,)`` current episode time of each episode [s] (0 at step 0, i.e. at log time ``start``)."""
        return self.steps * self.spec.dt

    def reset(self, seeds: np.ndarray | list[int], mask: np.ndarray | None = None) -> np.ndarray:
        """Start episodes at step 0; returns the initial prior means ``(B, N, 6)`` [p, v].

        Args:
            seeds: ``(B,)`` episode seeds (entries outside ``mask`` are ignored); a seed
                only changes the initial-prior perturbation.
            mask: optional ``(B,)`` bool: reset only these episodes; the others keep running.
        """
        seeds, idx = reset_indices(seeds, mask, self.batch_size)
        if idx.size == 0:
            return self.x0
        self.seeds[idx] = seeds[idx]
        self.steps[idx] = 0
        rec, f, buf = self.recording, self.spec.filter, self.buffers
        buf.pos[idx, 0] = rec.pos[0]
        buf.vel[idx, 0] = rec.vel[0]
        buf.imu[idx] = 0.0
        buf.z[idx] = 0.0
        buf.valid[idx] = False
        buf.label[idx] = False
        buf.injected[idx] = 0.0
        buf.error_label[idx] = False
        buf.systematic[idx] = 0.0
        for b in idx:
            seed = int(self.seeds[b])
            for d in range(3):
                # the same streams as the simulated world's initial prior (UAV 0)
                self.x0[b, 0, d] = rec.pos[0, d] + f.init_pos_sigma * normal(seed, 0, _INIT, 10_000 + d)
                self.x0[b, 0, 3 + d] = rec.vel[0, d] + f.init_vel_sigma * normal(seed, 0, _INIT, 10_003 + d)
        return self.x0

    def sense(self) -> SenseBuffers:
        """Advance every episode by one step and fill the step buffers from the recording.

        An episode past the end of the recording keeps reading its last step (the core
        never scores it: it is done after ``spec.n_steps`` updates).
        """
        self.steps += 1
        rec, buf = self.recording, self.buffers
        k = np.minimum(self.steps, rec.n_steps)
        buf.pos[:, 0] = rec.pos[k]
        buf.vel[:, 0] = rec.vel[k]
        buf.imu[:, 0] = rec.imu[k]
        buf.z[:, 0, :, 0] = rec.z[k]
        buf.valid[:, 0] = rec.valid[k]
        buf.label[:, 0] = rec.label[k]
        buf.injected[:, 0] = np.abs(rec.residual[k])
        buf.systematic[:, 0, :, 0] = rec.residual[k]
        # error labels (labels.own_sigmas of a range): |e| / σ above the threshold
        buf.error_label[:, 0] = rec.valid[k] & (np.abs(rec.residual[k]) / self.layout.sigma[0]
                                             > self.label_threshold[0])
        return buf


__all__ = ["RecordedWorld"]
