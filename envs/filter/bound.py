"""The information bound: a posterior Cramér–Rao bound of the swarm's positions, with clairvoyant exclusion.

What it is. Per episode, along the TRUE trajectory, the posterior Cramér–Rao bound (PCRLB) of
Tichavský, Muravchik and Nehorai (1998) over the joint state of the swarm, given the
measurements that are present and NOT biased: the channel-steps whose own injected
systematic error (NLOS bias, GPS drift) exceeds k·σ are left out by the truth (a clairvoyant
exclusion, ``bound_labels``), and the IMU-fault windows are known (not their bias). It is a
floor for estimators that are told the same: the privileged ``oracle`` and
``centralized-oracle`` (``tests/test_bound_property.py``); a non-privileged method may in
principle use a biased channel's residual information and is not bounded by it in theory.

State per UAV: x_i = [p_i, v_i, (b_i), (f_i)]: position, velocity, and where the task has them
the per-episode accelerometer bias b_i (``Sensors.imu_bias_sigma``: a random constant,
b_i ~ N(0, σ_b² I)) and the IMU-fault bias f_i (a random constant drawn at each fault onset,
f_i ~ N(0, σ_f² I), σ_f² = ‖β‖²/3 of the injected β, active inside the window only:
``fault_variance``). The accelerometer reads u = a + b + f + n, n ~ N(0, σ_imu² I), so

    p⁺ = p + dt·v − dt²/2·(b + f + n),   v⁺ = v − dt·(b + f + n),   b⁺ = b,   f⁺ = f

(``cekf.predict_uav``'s model F = [[I, dt·I], [0, I]], Q = σ_imu² G Gᵀ, G = [dt²/2·I; dt·I],
with the biases integrated like the acceleration they corrupt). The recursion

    J₀ = P₀⁻¹,   C_k⁻ = Q + F J_{k−1}⁻¹ Fᵀ,   J_k = (C_k⁻)⁻¹ + Σ_c E_{x ~ N(x_k, C_k⁻)}[H_c(x)ᵀ R_c⁻¹ H_c(x)]

with P₀ the filter's initial covariance (``cekf.initial_covariance``) and the bias priors,
H_c each channel's Jacobian over the joint state (a peer range ‖p_i − p_j‖ or relative
position p_j − p_i has a block for both UAVs), R_c its nominal variance (``ChannelLayout.r0``).
The bound of UAV i is tr[J_k⁻¹] over its position block.

Expected information (bound v2). Tichavský's measurement term is an expectation over the
state; bound v1 took it at the truth, E[HᵀR⁻¹H] ≈ H(x_k)ᵀR⁻¹H(x_k). That is the Fisher
information of a (locally) unbiased estimator, and it is no floor where a range is flat to
first order: where the ranging framework is (near-)planar, a displacement δ of a UAV normal
to the plane of its peers changes each of its ranges by δ²/(2r), by nothing to first order,
so the ranges gave the bound no out-of-plane information while an EKF, linearised at its own
estimate, draws it from the curvature (a biased estimator, which a CRB at the truth does not
bound). That was the NLOS-v1 violation (``n_uav=8``, anchors within 14 m, test seeds
1 000 000–003: the swarm flies at z = 2 m exactly; bound v1 1.102 m against the oracle's
0.785 m and the centralised EKF's 0.856 m (0.45 m on one seed), the gap all in z and, through
the anchors' heights, in x: bound v1 per axis 0.12 / 0.013 / 0.95 m², the centralised EKF
0.045 / 0.018 / 0.29 m² on seed 1 000 001). Bound v2 takes the expectation over
x ~ N(x_k, C_k⁻), the predicted spread of the bound itself: per step this is the Bayesian
(Van Trees 1968) information of a Gaussian prior N(x_k, C_k⁻), a floor for biased estimators
too, and the recursion is Tichavský's with the state density at each step approximated by
that Gaussian (as the conditional PCRLB of Zuo, Niu and Varshney 2011 evaluates its
expectations over an approximate filtering density). A linear channel's H is constant; a
range's gradient g (g = d/‖d‖ of the 3-vector d = p_i − q, q an anchor or the neighbour p_j;
the difference of two such for TDOA) is averaged by the third-degree spherical-radial
cubature rule (Arasaratnam and Haykin 2009): E[g gᵀ] ≈ (1/6) Σ_± Σ_c g(d̄ ± √3 L e_c) g(·)ᵀ,
L Lᵀ = Σ_d the 3×3 covariance of d read from C_k⁻ (A_ii; for a peer A_ii + A_jj − A_ij − A_ji).
A range's information keeps its trace (1/σ² per row) but spreads across the directions the
prior leaves uncertain: for d ~ N(d̄, Σ), E[g gᵀ] = ūūᵀ + (P⊥ΣP⊥ − tr(P⊥Σ) ūūᵀ)/r² + O(σ⁴/r⁴),
P⊥ = I − ūūᵀ. Where the spread is small against the ranges this is the bound at the truth
(``test_bound``: within 2 % for a UAV held by a landmark); NLOS-v1's variant above: 0.310 m.
It is an approximation of the PCRLB's expectation, not an exact bound of the fixed-truth
experiment: no bound holds for every biased estimator at one fixed truth (the constant
estimator at the truth has error 0), hence the property test.

Hybrid GPS noise (``specs.HybridNoise``). R_c of a fix is its nominal σ² (``Sensors.gps_sigma``)
whatever the model, and every fix enters (the heavy-tail excess is not in ``injected``). For
non-Gaussian additive noise the bound's measurement term is Hᵀ I_v H, I_v the Fisher
information of the noise density, so R_c⁻¹ ⪰ I_v keeps it a lower bound:

- mixture (v1), σ = σ_g = ``gauss_sigma``: Fisher information is convex in the density and a
  trivariate t of scale σ_t has I = (ν+3)/((ν+5) σ_t²) I, so
  I_v ⪯ [(1 − p)/σ_g² + p (ν+3)/((ν+5) σ_t²)] I ⪯ I/σ_g² whenever σ_t ≥ σ_g. The bound then
  holds, conservatively: it treats every fix as Gaussian with the mixture's core σ_g, while
  the mixture's actual spread per axis is larger, var = (1 − p) σ_g² + p σ_t² E[ν/(ν − 2)]
  (infinite for ν ≤ 2). With σ_t < σ_g it may not hold.
- weighted sum (v0): v = a·t + (1 − a)·g is nearly Gaussian with a spread *below* the nominal
  σ (std 0.91 / 0.77 / 0.72 m at a = 0.1 / 0.3 / 0.5 against 1 m), so its Fisher information
  exceeds 1/σ² and on those tasks the bound is not strictly a lower bound.

GNSS error correlated in time (``Sensors.gps_correlation_time`` > 0). A Gauss–Markov error of the
same stationary σ carries less position information over a run of fixes than white noise
(averaging n fixes shrinks a white error by √n, a correlated one by much less while n·dt ≲ τ), so
taking the fixes as white would credit them with information they do not have. On such a task
``pcrlb`` runs ``bound_gnss.pcrlb_correlated_gnss``: the same recursion, dense, with the 3 error
states of each receiver in the joint state (ε⁺ = φ ε + w, z = p + ε), which the fast path's
position-only measurement structure does not take. (Added with the first task that has such a
receiver, GradualFault-v2, before any result of it shipped; every other task's bound is unchanged.)

Fast path. The dynamics are linear, so the recursion is a Kalman covariance recursion with
the expected information. ``pcrlb`` runs it in covariance form C = J⁻¹ on the blocks
A = C_pp (3N × 3N), B = C_pr (3N × 3N·m), V = C_rr, r = [v, (b), (f)] the other states of all
UAVs (m = 1, 2 or 3 components; a bias of σ_b = 0 and a batch without IMU faults carry no
state), which exploits the structure:
- the prediction C⁻ = F C Fᵀ + Q is elementwise on the 3N × 3N blocks (F and Q act on each
  UAV alone and are scalar per block): O(m²(3N)²), no factorisation;
- every channel measures positions only, so the measurement information Λ = Σ E[HᵀR⁻¹H] is a
  3N × 3N matrix assembled by 3×3 blocks (a peer adds to the ii, jj, ij and ji blocks), and
  the update conditions the positions only (the other states' regression on the positions
  is unchanged): two 3N × 3N symmetric positive-definite inverses and three products per
  step, never a 6N × 6N factorisation (``update_covariance``);
- the inverses are Cholesky-based block inversions (``spd_inverse``) whose pivots double
  as the positive-definiteness test: a bound that loses it numerically is reported
  (``Pcrlb.failed_at``), never returned;
- episodes with identical inputs (a fixed trajectory, scheduled faults) are computed once.

The kernels are in ``bound_kernel``; ``bound_reference`` is the literal information-form
transcription (dense inverses of the joint state); tests hold the two equal.

History. v1 (``BOUND_VERSION`` 1, shipped in the standard-v1 results): 6N state, information at the
truth, no accelerometer or fault bias. On the v0 tasks it measured, with the planar limit above:
Indoor-v0 with a 60° camera cone (range 6 m, σ_imu 0.5 m/s²) bound 1.223 m, uniform CEKF
0.47 m, a centralised EKF 0.33 m. v2 (2): the expectation, the bias states.
"""

from __future__ import annotations

import hashlib
from typing import NamedTuple

import numpy as np

from swarmloc.envs.filter.bound_kernel import pcrlb_kernel
from swarmloc.envs.world.labels import LABEL_SIGMAS
from swarmloc.envs.tasks.specs import TaskSpec

#: A channel-step enters the bound unless its own injected systematic error (NLOS bias, GPS
#: drift: ``SenseBuffers.injected``) exceeds this many nominal σ: the k of the error labels
#: (``labels.LABEL_SIGMAS``), so the bound leaves out what the error labels call a fault of the
#: measurement itself. (Labels v1 judge a 3-vector channel by a wider radius and count the
#: heavy-tail excess of hybrid GPS noise too; no v0 task's GPS error comes near either.)
BOUND_LABEL_SIGMAS = LABEL_SIGMAS
#: bump whenever the bound's maths or inputs change (it keys the persistent cache)
BOUND_VERSION = 2


class BoundInputs(NamedTuple):
    """Everything the recursion needs for B episodes of one task.

    Shapes: T steps (1 … T, the filter's updates), B episodes, N UAVs, L channels per UAV,
    A anchors, M landmarks.

    Attributes:
        dt: step length [s].
        imu_sigma: accelerometer noise σ [m/s²] (Q = σ² G Gᵀ).
        bias_sigma: σ_b of the per-episode accelerometer bias, a random constant b ~ N(0, σ_b² I)
            per UAV (``Sensors.imu_bias_sigma``) [m/s²]; 0: no bias state.
        fault_var: ``(T, B, N)`` per-axis prior variance σ_f² of the IMU-fault bias active on a UAV at
            a step (0: no fault there) [m²/s⁴]; a new value starts a new fault (its bias is drawn afresh).
        p0_diag: ``(6,)`` diagonal of one UAV's initial covariance [m², m²/s²] (p then v).
        kind, target: ``(N, L)`` int64 channel kind and the anchor / UAV / landmark it refers to.
        r0: ``(N, L)`` nominal variance per scalar row [m²].
        anchors: ``(A, 3)``; landmarks ``(M, 3)`` [m].
        pos: ``(T, B, N, 3)`` true positions at steps 1 … T [m].
        use: ``(T, B, N, L)`` bool: the channel-step enters (present and not labelled faulty).
        gps_tau: the GNSS error's correlation time [s] (``Sensors.gps_correlation_time``); 0: white fixes (the
            fast path); > 0: the receivers' errors are states (``bound_gnss``).
    """

    dt: float
    imu_sigma: float
    bias_sigma: float
    fault_var: np.ndarray
    p0_diag: np.ndarray
    kind: np.ndarray
    target: np.ndarray
    r0: np.ndarray
    anchors: np.ndarray
    landmarks: np.ndarray
    pos: np.ndarray
    use: np.ndarray
    gps_tau: float = 0.0


class Pcrlb(NamedTuple):
    """The bound of every UAV at every step.

    Attributes:
        pos_var: ``(T, B, N)`` tr[J_k⁻¹] over each UAV's position block [m²] (NaN after a failure).
        failed_at: ``(B,)`` first step index (0-based) whose bound is not positive definite
            numerically; −1 where the recursion ran to the end.
    """

    pos_var: np.ndarray
    failed_at: np.ndarray


def unsupported_reason(spec: TaskSpec) -> str | None:
    """Why the bound of ``spec`` is not defined (None: it is).

    Args:
        spec: the task.

    Returns:
        None, or a one-line reason: a recorded flight (truth and channel faults come from a
        log, not from the world the bound replays), a swarm whose absolute position is
        unobservable (no anchor, landmark or GPS: translation and yaw are a gauge, which the
        task's alignment removes from its score but not from the bound), or a sensor the
        bound does not model (visual odometry).
    """
    if spec.trajectory.kind == "recorded":
        return (f"{spec.task_id} replays a recorded flight: the bound is computed on the simulated world "
                "and is not defined for recorded data")
    if not (spec.anchors or spec.landmarks or spec.sensors.gps_sigma):
        return (f"{spec.task_id} has no anchor, landmark or GPS: the swarm's translation and yaw are "
                "unobservable (a gauge the score removes by alignment), so no finite position bound exists")
    if spec.scoring.align_first_seconds > 0:
        return f"{spec.task_id} is scored after an alignment that the bound does not model"
    if spec.sensors.velocity_sigma is not None:
        return f"{spec.task_id} has visual odometry, which the bound does not model"
    return None


def bound_labels(valid: np.ndarray, injected: np.ndarray, sigma: np.ndarray,
                 label_sigmas: float = BOUND_LABEL_SIGMAS) -> np.ndarray:
    """Channel-steps the bound leaves out: present and with an own systematic error above k·σ.

    The measurement's own error only (``SenseBuffers.injected``: NLOS bias, GPS drift), not
    the neighbour-estimate part that the world's ``label`` adds to a peer link whose
    neighbour has an IMU fault: the bound estimates every UAV jointly, so that range is
    informative whatever the neighbour's filter believes.

    Args:
        valid: ``(..., N, L)`` measurement present.
        injected: ``(..., N, L)`` magnitude of the injected error [m].
        sigma: ``(N, L)`` nominal σ per scalar row [m].
        label_sigmas: k.

    Returns:
        ``(..., N, L)`` bool.
    """
    return np.asarray(valid, dtype=bool) & (np.asarray(injected) > label_sigmas * np.asarray(sigma))


def fault_variance(schedule, dt: float, n_steps: int, n_uav: int) -> np.ndarray:
    """Per step and UAV, the prior variance per axis of the IMU-fault bias the bound carries.

    The world adds a window's bias β to a faulty UAV's accelerometer for ``start <= t < end``
    (``faults.FaultSchedule.imu_time``, ``imu_bias``, ``imu_nodes``; t = k·dt at step k). The
    bound knows the window (clairvoyantly, as it knows which channels are biased) but not β:
    inside it the UAV's acceleration carries an unknown constant f ~ N(0, σ_f² I) with
    σ_f² = ‖β‖²/3, the isotropic prior of β's energy. Overlapping windows of one UAV add their
    variances (their sum is one new unknown from the second onset).

    Args:
        schedule: a ``FaultSchedule`` of B episodes (None: no IMU fault).
        dt: step [s]; n_steps: T; n_uav: N.

    Returns:
        ``(T, B, N)`` σ_f² [m²/s⁴], 0 where no fault is active.
    """
    if schedule is None:
        raise ValueError("the bound needs the episodes' fault schedule (world.schedule)")
    n_b = schedule.imu_time.shape[0]
    out = np.zeros((n_steps, n_b, n_uav))
    t = dt * np.arange(1, n_steps + 1)
    for wi in range(schedule.imu_time.shape[1]):
        start, end = schedule.imu_time[:, wi, 0], schedule.imu_time[:, wi, 1]
        inside = (t[:, None] >= start[None]) & (t[:, None] < end[None])  # (T, B)
        var = np.sum(np.asarray(schedule.imu_bias[:, wi], dtype=float) ** 2, axis=-1) / 3.0  # (B,)
        out += (inside[:, :, None] & schedule.imu_nodes[None, :, wi, :]) * var[None, :, None]
    return out


class BoundRecorder:
    """Collects the bound's inputs step by step from a world's buffers.

    Feed it the world's step buffers once per filter update, in order (steps 1 … T): for
    ``World.sense`` that is every sensed step; inside a ``LinkTrustCore`` (or
    ``TrustEnvBatch``), whose world always holds the *pending* step, ``core.world.buffers``
    after the reset and after each of the first T − 1 steps. A runner that already steps a
    world (e.g. the uniform reference rollout) thus gets the bound without a second
    simulation.

    Args:
        spec: the task; layout, anchors, landmarks: the world's (``world.layout`` …).
        n_episodes: B.
        label_sigmas: k of ``bound_labels``.
    """

    def __init__(self, spec: TaskSpec, layout, anchors: np.ndarray, landmarks: np.ndarray, n_episodes: int,
                 label_sigmas: float = BOUND_LABEL_SIGMAS):
        self.spec, self.layout, self.label_sigmas = spec, layout, float(label_sigmas)
        self.anchors = np.ascontiguousarray(anchors, dtype=float).reshape(-1, 3)
        self.landmarks = np.ascontiguousarray(landmarks, dtype=float).reshape(-1, 3)
        n_t, n, n_l = spec.n_steps, spec.n_uav, layout.n_channels
        self.pos = np.empty((n_t, n_episodes, n, 3))
        self.use = np.zeros((n_t, n_episodes, n, n_l), dtype=np.bool_)
        self.steps = 0

    def record(self, pos: np.ndarray, valid: np.ndarray, injected: np.ndarray) -> None:
        """Record the next step: truth ``(B, N, 3)``, validity and injected error ``(B, N, L)``."""
        k = self.steps
        if k >= self.pos.shape[0]:
            raise ValueError(f"{self.spec.task_id} has {self.pos.shape[0]} steps; step {k + 1} is one too many")
        self.pos[k] = pos
        self.use[k] = valid & ~bound_labels(valid, injected, self.layout.sigma, self.label_sigmas)
        self.steps = k + 1

    def inputs(self, schedule) -> BoundInputs:
        """The recorded episodes as ``BoundInputs`` (every step must have been recorded).

        Args:
            schedule: the episodes' ``FaultSchedule`` (``world.schedule``): its IMU-fault windows
                (``fault_variance``).
        """
        if self.steps != self.pos.shape[0]:
            raise ValueError(f"{self.steps} of {self.pos.shape[0]} steps of {self.spec.task_id} recorded")
        f, lay = self.spec.filter, self.layout
        return BoundInputs(
            dt=float(self.spec.dt), imu_sigma=float(self.spec.sensors.imu_sigma),
            bias_sigma=float(self.spec.sensors.imu_bias_sigma),
            fault_var=fault_variance(schedule, self.spec.dt, self.pos.shape[0], self.pos.shape[2]),
            p0_diag=np.array([f.init_pos_sigma**2] * 3 + [f.init_vel_sigma**2] * 3),
            kind=np.ascontiguousarray(lay.kind), target=np.ascontiguousarray(lay.target),
            r0=np.ascontiguousarray(lay.r0), anchors=self.anchors, landmarks=self.landmarks, pos=self.pos,
            use=self.use, gps_tau=float(self.spec.sensors.gps_correlation_time))


def record_inputs(spec: TaskSpec, seeds: np.ndarray | list[int],
                  label_sigmas: float = BOUND_LABEL_SIGMAS) -> tuple[BoundInputs, object]:
    """Run B episodes of the world and collect what the bound needs.

    Args:
        spec: a simulated task.
        seeds: ``(B,)`` episode seeds.
        label_sigmas: k of ``bound_labels``.

    Returns:
        ``(inputs, world)``; the world (after its last step) holds the episodes' fault
        schedule, which the scoring of some tasks needs.
    """
    from swarmloc.envs.world.worlds import make_world

    seeds = np.asarray(seeds, dtype=np.int64)
    world = make_world(spec, len(seeds))
    world.reset(seeds)
    rec = BoundRecorder(spec, world.layout, world.anchors, world.landmarks, len(seeds), label_sigmas)
    for _ in range(spec.n_steps):
        buf = world.sense()
        rec.record(buf.pos, buf.valid, buf.injected)
    return rec.inputs(world.schedule), world


def distinct_episodes(inputs: BoundInputs) -> tuple[np.ndarray, np.ndarray]:
    """Episodes whose inputs differ: the bound depends on the truth, the channels used and the IMU faults only.

    Tasks with a fixed trajectory and scheduled faults give every seed the same bound; it is
    computed once.

    Returns:
        ``(first (E,), which (B,))``: the first episode of each distinct input, and for every
        episode the index into ``first`` of its twin.
    """
    first: list[int] = []
    seen: dict[bytes, int] = {}
    which = np.empty(inputs.pos.shape[1], dtype=np.int64)
    for b in range(inputs.pos.shape[1]):
        key = hashlib.sha256(np.ascontiguousarray(inputs.pos[:, b]).tobytes()
                             + np.packbits(inputs.use[:, b]).tobytes()
                             + np.ascontiguousarray(inputs.fault_var[:, b]).tobytes()).digest()
        if key not in seen:
            seen[key] = len(first)
            first.append(b)
        which[b] = seen[key]
    return np.array(first, dtype=np.int64), which


def pcrlb(inputs: BoundInputs) -> Pcrlb:
    """The bound of every UAV at every step of B episodes (fast path).

    Args:
        inputs: see ``BoundInputs``.

    Returns:
        ``Pcrlb`` (pos_var ``(T, B, N)``, failed_at ``(B,)``).
    """
    if inputs.gps_tau > 0:  # correlated GNSS errors: their states in a dense recursion (bound_gnss)
        from swarmloc.envs.filter.bound_gnss import pcrlb_correlated_gnss

        return pcrlb_correlated_gnss(inputs)
    n_t, n_b, n = inputs.pos.shape[:3]
    pos_var = np.full((n_t, n_b, n), np.nan)
    failed_at = np.full(n_b, -1, dtype=np.int64)
    w = inputs._replace(pos=np.ascontiguousarray(inputs.pos, dtype=np.float64),
                        use=np.ascontiguousarray(inputs.use, dtype=np.bool_),
                        p0_diag=np.ascontiguousarray(inputs.p0_diag, dtype=np.float64),
                        fault_var=np.ascontiguousarray(inputs.fault_var, dtype=np.float64),
                        dt=float(inputs.dt), imu_sigma=float(inputs.imu_sigma), bias_sigma=float(inputs.bias_sigma))
    first, which = distinct_episodes(w)
    pcrlb_kernel(w, first, pos_var, failed_at)
    # twins share the bound of the first episode with their inputs
    pos_var[:] = pos_var[:, first[which]]
    failed_at[:] = failed_at[first[which]]
    return Pcrlb(pos_var=pos_var, failed_at=failed_at)


def bound_rmse(pos_var: np.ndarray, steps: np.ndarray, nodes: np.ndarray) -> float:
    """sqrt(mean over the scored steps and UAVs of tr[J_k⁻¹]_pos) of one episode.

    Args:
        pos_var: ``(T, N)`` one episode's ``Pcrlb.pos_var``.
        steps: ``(T,)`` bool scored steps; nodes: ``(N,)`` bool scored UAVs.

    Returns:
        The bound on the episode's RMSE over those steps and UAVs [m] (NaN if the
        selection is empty or the recursion failed inside it).
    """
    sel = np.asarray(pos_var)[np.asarray(steps, bool)][:, np.asarray(nodes, bool)]
    if sel.size == 0:
        return float("nan")
    return float(np.sqrt(np.mean(sel)))
