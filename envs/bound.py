"""The information bound: the posterior Cramér–Rao bound of the swarm's positions.

Per episode, along the TRUE trajectory, the bound of Tichavský, Muravchik and Nehorai (1998)
over the joint 6N state of the swarm, given the measurements that are present and not
labelled faulty:

    J₀ = P₀⁻¹,   J_k = (Q + F J_{k−1}⁻¹ Fᵀ)⁻¹ + Σ_c H_cᵀ R_c⁻¹ H_c

with F, Q the CEKF's IMU-driven constant-acceleration model (``cekf.predict_uav``: per UAV
F = [[I, dt·I], [0, I]], Q = σ_imu² G Gᵀ, G = [dt²/2·I; dt·I]), P₀ the filter's initial
covariance (``cekf.initial_covariance``), H_c each channel's Jacobian at the true positions
(a peer range ‖p_i − p_j‖ or relative position p_j − p_i has a block for both UAVs) and R_c
its nominal variance (``ChannelLayout.r0``). No estimator that uses only those measurements
and the IMU model can have a lower mean-square error than tr[J_k⁻¹] over a UAV's position
block, whatever it believes about its neighbours: the bound estimates the swarm jointly.

Fast path. The dynamics are linear, so the recursion is a Kalman covariance recursion with
the Jacobians at the truth. ``pcrlb`` runs it in covariance form C = J⁻¹, ordered
[positions (3N); velocities (3N)], which exploits the structure:
- the prediction C⁻ = F C Fᵀ + Q is block-local (F and Q are the same 6×6 model for every
  UAV), O((6N)²) with no factorisation;
- every channel measures positions only, so the measurement information Λ = Σ HᵀR⁻¹H is a
  (3N × 3N) matrix assembled by 3×3 blocks (a peer adds to the ii, jj, ij and ji blocks),
  and the update conditions only the positions: with S = C⁻_pp,
      P = (S⁻¹ + Λ)⁻¹ = S (I + ΛS)⁻¹,  C_vp⁺ = C_vp S⁻¹ P = C_vp (I + ΛS)⁻¹,
      C_vv⁺ = C_vv − C_vp⁺ Λ C_pv
  (the velocities' regression on the positions is unchanged by a position measurement).
  One LU solve with (I + SΛ) and 2·3N right-hand sides and three (3N)³ products per step;
  no explicit inverse (a solve is cheaper and more accurate), no 6N × 6N factorisation.
- every step's position block P is checked with a Cholesky factorisation: a bound that
  loses positive definiteness numerically is reported (``failed_at``), never returned.

``bound_reference`` is the literal information-form transcription (dense 6N × 6N inverses);
tests hold the two equal.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .channels import ANCHOR, GPS, LANDMARK, PEER, PEER_REL
from .specs import TaskSpec

#: A channel-step enters the bound unless its own injected systematic error (NLOS bias, GPS
#: drift: ``SenseBuffers.injected``) exceeds this many nominal σ. One place to change it; it
#: follows the labels-v1 threshold k.
BOUND_LABEL_SIGMAS = 3.0
#: bump whenever the bound's maths or inputs change (it keys the persistent cache)
BOUND_VERSION = 1

_MIN_RANGE = 1e-9  # the CEKF skips a range at zero distance (no Jacobian): so does the bound


class BoundInputs(NamedTuple):
    """Everything the recursion needs for B episodes of one task.

    Shapes: T steps (1 … T, the filter's updates), B episodes, N UAVs, L channels per UAV,
    A anchors, M landmarks.

    Attributes:
        dt: step length [s].
        imu_sigma: accelerometer noise σ [m/s²] (Q = σ² G Gᵀ).
        p0_diag: ``(6,)`` diagonal of one UAV's initial covariance [m², m²/s²] (p then v).
        kind, target: ``(N, L)`` int64 channel kind and the anchor / UAV / landmark it refers to.
        r0: ``(N, L)`` nominal variance per scalar row [m²].
        anchors: ``(A, 3)``; landmarks ``(M, 3)`` [m].
        pos: ``(T, B, N, 3)`` true positions at steps 1 … T [m].
        use: ``(T, B, N, L)`` bool: the channel-step enters (present and not labelled faulty).
    """

    dt: float
    imu_sigma: float
    p0_diag: np.ndarray
    kind: np.ndarray
    target: np.ndarray
    r0: np.ndarray
    anchors: np.ndarray
    landmarks: np.ndarray
    pos: np.ndarray
    use: np.ndarray


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
    from .worlds import make_world

    seeds = np.asarray(seeds, dtype=np.int64)
    world = make_world(spec, len(seeds))
    world.reset(seeds)
    lay = world.layout
    n_t, n_b = spec.n_steps, len(seeds)
    pos = np.empty((n_t, n_b, spec.n_uav, 3))
    use = np.empty((n_t, n_b, spec.n_uav, lay.n_channels), dtype=np.bool_)
    for k in range(n_t):
        buf = world.sense()
        pos[k] = buf.pos
        use[k] = buf.valid & ~bound_labels(buf.valid, buf.injected, lay.sigma, label_sigmas)
    f = spec.filter
    inputs = BoundInputs(
        dt=float(spec.dt), imu_sigma=float(spec.sensors.imu_sigma),
        p0_diag=np.array([f.init_pos_sigma**2] * 3 + [f.init_vel_sigma**2] * 3),
        kind=np.ascontiguousarray(lay.kind), target=np.ascontiguousarray(lay.target),
        r0=np.ascontiguousarray(lay.r0), anchors=np.ascontiguousarray(world.anchors, dtype=float),
        landmarks=np.ascontiguousarray(world.landmarks, dtype=float), pos=pos, use=use)
    return inputs, world


@njit(cache=True)
def _add_block(Lam, i, j, u0, u1, u2, s):
    """Λ[3i:3i+3, 3j:3j+3] += s·u uᵀ."""
    u = (u0, u1, u2)
    for r in range(3):
        for c in range(3):
            Lam[3 * i + r, 3 * j + c] += s * u[r] * u[c]


@njit(cache=True)
def _add_diag(Lam, i, j, s):
    """Λ[3i:3i+3, 3j:3j+3] += s·I."""
    for d in range(3):
        Lam[3 * i + d, 3 * j + d] += s


@njit(cache=True)
def position_information(pos, use, kind, target, r0, anchors, landmarks, Lam):
    """Λ = Σ_c H_cᵀ R_c⁻¹ H_c on the positions ``(3N, 3N)`` of one step, by 3×3 blocks (in place).

    Args:
        pos: ``(N, 3)`` true positions; use ``(N, L)``; kind, target, r0 ``(N, L)``.
        anchors ``(A, 3)``, landmarks ``(M, 3)``.
        Lam: ``(3N, 3N)`` output (overwritten).

    Returns:
        The number of channels that entered.
    """
    Lam[:] = 0.0
    n, n_l = kind.shape
    used = 0
    for i in range(n):
        for l in range(n_l):
            if not use[i, l]:
                continue
            ch = kind[i, l]
            j = target[i, l]
            w = 1.0 / r0[i, l]
            if ch == ANCHOR or ch == PEER:
                if ch == ANCHOR:
                    d0, d1, d2 = pos[i, 0] - anchors[j, 0], pos[i, 1] - anchors[j, 1], pos[i, 2] - anchors[j, 2]
                else:
                    d0, d1, d2 = pos[i, 0] - pos[j, 0], pos[i, 1] - pos[j, 1], pos[i, 2] - pos[j, 2]
                rng = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                if rng < _MIN_RANGE:
                    continue
                # h = ‖p_i − q‖: H_i = uᵀ, u = (p_i − q)/‖p_i − q‖; a peer q = p_j has H_j = −uᵀ
                u0, u1, u2 = d0 / rng, d1 / rng, d2 / rng
                _add_block(Lam, i, i, u0, u1, u2, w)
                if ch == PEER:
                    _add_block(Lam, j, j, u0, u1, u2, w)
                    _add_block(Lam, i, j, u0, u1, u2, -w)
                    _add_block(Lam, j, i, u0, u1, u2, -w)
            elif ch == GPS or ch == LANDMARK:
                # h = p_i (GPS) or m − p_i (landmark): H_i = ±I, Hᵀ R⁻¹ H = I/r0
                _add_diag(Lam, i, i, w)
            elif ch == PEER_REL:
                # h = p_j − p_i: H_i = −I, H_j = I
                _add_diag(Lam, i, i, w)
                _add_diag(Lam, j, j, w)
                _add_diag(Lam, i, j, -w)
                _add_diag(Lam, j, i, -w)
            used += 1
    return used


@njit(cache=True)
def predict_covariance(C, dt, q):
    """C⁻ = F C Fᵀ + Q in place, C ``(6N, 6N)`` ordered [p (3N); v (3N)].

    F = [[I, dt I], [0, I]] on the blocks A = C_pp, B = C_pv, V = C_vv:
    A⁻ = A + dt (B + Bᵀ) + dt² V,  B⁻ = B + dt V,  V⁻ = V; Q = q G Gᵀ adds q·dt⁴/4, q·dt³/2, q·dt²
    to the diagonals of the pp, pv and vv blocks (``cekf.predict_uav`` for the whole swarm).
    """
    n = C.shape[0] // 2
    h2 = 0.5 * dt * dt
    for r in range(n):
        for c in range(n):
            vv = C[n + r, n + c]
            pp = C[r, c] + dt * (C[r, n + c] + C[n + r, c]) + dt * dt * vv
            C[r, n + c] = C[r, n + c] + dt * vv
            C[n + r, c] = C[n + r, c] + dt * vv
            C[r, c] = pp
    for d in range(n):
        C[d, d] += q * h2 * h2
        C[d, n + d] += q * h2 * dt
        C[n + d, d] += q * h2 * dt
        C[n + d, n + d] += q * dt * dt


@njit(cache=True)
def update_covariance(C, Lam):
    """Condition C ``(6N, 6N)`` [p; v] on position information Λ ``(3N, 3N)`` in place.

    With S = C_pp (see the module docstring):
        P = S (I + ΛS)⁻¹,  C_vp⁺ = C_vp (I + ΛS)⁻¹,  C_vv⁺ = C_vv − C_vp⁺ Λ C_pv.
    Both first products come from one LU solve (I + SΛ) X = [S, C_pv] (the transposed system:
    S and Λ are symmetric), not from inverses.

    Returns:
        The posterior position block P ``(3N, 3N)`` (symmetrised), also written into C.
    """
    n = C.shape[0] // 2
    S = np.ascontiguousarray(C[:n, :n])
    Cpv = np.ascontiguousarray(C[:n, n:])
    # Gᵀ = I + S Λ
    Gt = S @ Lam
    for d in range(n):
        Gt[d, d] += 1.0
    rhs = np.empty((n, 2 * n))
    rhs[:, :n] = S
    rhs[:, n:] = Cpv
    # (I + SΛ) X = [S, C_pv]:  X = [P, C_pv⁺] (Pᵀ = P)
    X = np.linalg.solve(Gt, rhs)
    P = 0.5 * (X[:, :n] + X[:, :n].T)
    Cpv_post = np.ascontiguousarray(X[:, n:])
    # C_vv⁺ = C_vv − C_vp⁺ Λ C_pv
    LamCpv = Lam @ Cpv
    Cvv_post = np.ascontiguousarray(C[n:, n:]) - Cpv_post.T @ LamCpv
    C[:n, :n] = P
    C[:n, n:] = Cpv_post
    C[n:, :n] = Cpv_post.T
    C[n:, n:] = 0.5 * (Cvv_post + Cvv_post.T)
    return P


@njit(cache=True)
def _positive_definite(P):
    """Whether P is numerically positive definite (its Cholesky factorisation exists and is finite)."""
    try:
        L = np.linalg.cholesky(P)
    except Exception:  # noqa: BLE001 (numba raises a LinAlgError, caught here as Exception)
        return False
    return np.isfinite(L).all()


@njit(cache=True)
def _pcrlb_kernel(w, pos_var, failed_at):
    """The recursion for every episode (serial: the suite runs tasks one after another)."""
    n_t, n_b, n = w.pos.shape[0], w.pos.shape[1], w.pos.shape[2]
    q = w.imu_sigma * w.imu_sigma
    Lam = np.zeros((3 * n, 3 * n))
    C = np.zeros((6 * n, 6 * n))
    for b in range(n_b):
        # C₀ = P₀ (J₀ = P₀⁻¹): the filter's diagonal initial covariance
        C[:] = 0.0
        for i in range(n):
            for d in range(3):
                C[3 * i + d, 3 * i + d] = w.p0_diag[d]
                C[3 * n + 3 * i + d, 3 * n + 3 * i + d] = w.p0_diag[3 + d]
        failed_at[b] = -1
        for k in range(n_t):
            predict_covariance(C, w.dt, q)
            used = position_information(w.pos[k, b], w.use[k, b], w.kind, w.target, w.r0, w.anchors,
                                        w.landmarks, Lam)
            ok = True
            if used > 0:
                try:
                    P = update_covariance(C, Lam)
                except Exception:  # noqa: BLE001 (a singular system: numba raises LinAlgError)
                    ok = False
            else:
                P = np.ascontiguousarray(C[:3 * n, :3 * n])
            if ok:
                ok = _positive_definite(P)
            if not ok:
                failed_at[b] = k
                pos_var[k:, b, :] = np.nan
                break
            for i in range(n):
                pos_var[k, b, i] = P[3 * i, 3 * i] + P[3 * i + 1, 3 * i + 1] + P[3 * i + 2, 3 * i + 2]


def pcrlb(inputs: BoundInputs) -> Pcrlb:
    """The bound of every UAV at every step of B episodes (fast path).

    Args:
        inputs: see ``BoundInputs``.

    Returns:
        ``Pcrlb`` (pos_var ``(T, B, N)``, failed_at ``(B,)``).
    """
    n_t, n_b, n = inputs.pos.shape[:3]
    pos_var = np.full((n_t, n_b, n), np.nan)
    failed_at = np.full(n_b, -1, dtype=np.int64)
    w = inputs._replace(pos=np.ascontiguousarray(inputs.pos, dtype=np.float64),
                        use=np.ascontiguousarray(inputs.use, dtype=np.bool_),
                        p0_diag=np.ascontiguousarray(inputs.p0_diag, dtype=np.float64),
                        dt=float(inputs.dt), imu_sigma=float(inputs.imu_sigma))
    _pcrlb_kernel(w, pos_var, failed_at)
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
