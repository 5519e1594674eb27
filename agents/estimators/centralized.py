"""``centralized-oracle``: one EKF over the joint state of the whole swarm (privileged Track B reference).

Where the CEKF backbone runs one 6-state EKF per UAV and fuses a neighbour's broadcast estimate
(as a known point, or by covariance intersection), this estimator keeps the swarm's joint state
and its full covariance, as a fusion centre that receives every measurement would. It is the
achievable reference that shows what decentralization costs (docs/methods.md).

**State.** x = [p_1 … p_N, v_1 … v_N] (6N), positions first so that every channel, which measures
positions only, reads the leading 3N block; P is the full covariance with every cross-covariance
between UAVs. Where the task draws a constant accelerometer bias per UAV and episode
(``TaskFacts.imu_bias_sigma`` = σ_b > 0: the world's IMU reads u = a + b + noise), the state adds
b_1 … b_N (9N), a random constant with prior N(0, σ_b² I), as the information bound carries it.
Where the task injects IMU faults (``TaskFacts.imu_faults``: a faulty UAV's accelerometer reads
u = a + β inside its fault window), the state adds f_1 … f_N, the fault offset, as the bound carries
it (``bound.fault_variance``): the runner tells this privileged estimator each step's fault variance
σ_f² = ‖β‖²/3 per UAV (``PrivilegedInfo.imu_fault_variance``, the window clairvoyantly, not β), and
f_i is 0 and certain outside UAV i's window, a random constant N(0, σ_f² I) from its onset (P_ff
raised by the variance's increase), and back to 0 and certain at its end. Without it a blind faulty
UAV's drifting estimate stays confident and the joint update spreads its error to the healthy UAVs
(CascadedFault-v2, faults on: 0.54 m against uniform's 0.11 m).

**Prediction**, every UAV with its own IMU reading u_i, the CEKF's model (``cekf_reference.transition``)
with the offsets taken out: x_i⁻ = F x_i + G (u_i − b_i − f_i), b_i⁻ = b_i, f_i⁻ = f_i. On the 3N × 3N
blocks of P (k = 2 block kinds p, v; one more for b and for f), with the per-axis coefficients
f = [[1, dt], [0, 1]] (each offset adds a column −dt²/2, −dt and a 1 on its diagonal: k = 3 gives
[[1, dt, −dt²/2], [0, 1, −dt], [0, 0, 1]]) and q = σ_imu² G Gᵀ per axis (0 on the offsets), independent
between UAVs,

    P⁻[a, c] = Σ_{i, j} f[a, i] f[c, j] P[i, j] + q[a, c] I

(the nonzero f[a, i] only): O((kN)²), no kN × kN product.

**Update**, at the prior x⁻, with every valid channel of every UAV that the episode does not
label faulty. Each channel is a measurement of the joint state with the nominal R0 (trust 1):

| kind | h(x) | ∂h/∂p_i | ∂h/∂p_j |
|---|---|---|---|
| anchor | ‖p_i − a‖ | uᵀ | — |
| TDOA (a, b) | ‖p_i − a_b‖ − ‖p_i − a_a‖ | u_bᵀ − u_aᵀ | — |
| GPS | p_i | I | — |
| landmark | m − p_i | −I | — |
| peer range | ‖p_i − p_j‖ | uᵀ | −uᵀ |
| peer relative position | p_j − p_i | −I | I |

A peer link is a true joint measurement: its Jacobian has a block for both UAVs, and the joint
covariance holds their correlation, so nothing is counted twice (UAV i's channel to j and j's
channel to i are two independent measurements, each used once). The rows are linearised at
the same prior and R is diagonal, so their information adds up in the 3N × 3N position block,

    Λ = Σ_c H_cᵀ R_c⁻¹ H_c,   η = Σ_c H_cᵀ R_c⁻¹ y_c,   y_c = z_c − h_c(x⁻),

and, with A = P_pp⁻ and P_·p = P⁻ Eᵀ (the columns of the positions), the push-through identity
Hᵀ (H A Hᵀ + R)⁻¹ = (I + Λ A)⁻¹ Hᵀ R⁻¹ turns the m-row update (m up to N·L·3) into a 3N × 3N one:

    W = (I + Λ A)⁻¹,   M = W Λ,   K H = P_·p M E,   K y = P_·p W η,
    x⁺ = x⁻ + P_·p W η,
    P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ = P⁻ + P_·p (M A Mᵀ + W Λ Wᵀ − M − Mᵀ) P_·pᵀ

(the Joseph form written through M and W, so it stays positive semi-definite for the computed
gain; P is symmetrized after). It equals the CEKF's joint update for one UAV
(``tests/test_centralized.py``).

**Excluded.** A channel whose error label is set (``PrivilegedInfo.error_labels``: the
measurement's own systematic error, NLOS bias or GPS drift or heavy-tail excess, above k·σ,
``envs/world/labels.py``) does not enter; that is the set the information bound leaves out
(``bound.bound_labels``). The injected-fault labels also mark a peer link to a neighbour in an
IMU fault window; a joint filter estimates that neighbour itself, so the range is informative
and stays. Not modelled: visual odometry (``Measurements.velocity``).

**Cost** per step and episode (``joint_flops``): the prediction 2·nnz(f)²·(3N)² (nnz(f) = 3, or 6 with
the bias), the channel rows O(N·L), the update two 3N × 3N inversions and products (≈ 8 (3N)³) and
P_·p D P_·pᵀ (≈ 2·k·3N·(3N)² + 2·(k·3N)²·3N), in all ≈ 17·(3N)³ flops without the bias (0.2 MFLOP
at N = 8, 15 MFLOP at N = 32), ≈ 32·(3N)³ with it. Memory B·(3kN)² floats (B = 8, N = 32, k = 3: 6.4 MB).
``flops`` reports the whole swarm's count divided evenly among its UAVs.
"""

from __future__ import annotations

import numpy as np

from swarmloc.agents.estimators.dead_reckoning import cekf_prior
from swarmloc.agents.protocols import EstimatorOutput, Measurements, PrivilegedInfo, TaskFacts
from swarmloc.envs.filter.cekf_reference import transition
from swarmloc.envs.tasks.channels import ANCHOR, GPS, LANDMARK, PEER, PEER_REL, TDOA, tdoa_pair

#: a range shorter than this has no direction: the channel is skipped (as the CEKF does)
_MIN_RANGE = 1e-9
_RANGE_KINDS = (ANCHOR, PEER, TDOA)
_PEER_KINDS = (PEER, PEER_REL)


class JointLayout:
    """The static geometry of a task's channels, precomputed once per reset.

    Args:
        kind, target: ``(N, L)`` channel kinds and targets (``TaskFacts``).
        sigma: ``(N, L)`` nominal std per scalar row [m].
        anchors: ``(A, 3)``; landmarks: ``(M, 3)``.

    Attributes:
        kind: ``(N, L)``; scalar: ``(N, L)`` bool, a one-row (range or TDOA) channel.
        rows: ``(N, L, 3)`` 1 on the rows a channel has (row 0 for a scalar channel, all 3 otherwise).
        inv_r: ``(N, L, 3)`` R0⁻¹ per row (0 on absent rows).
        point: ``(N, L, 3)`` the fixed point of an anchor range (a), a landmark (m) or a TDOA's first anchor (a_a).
        point_b: ``(N, L, 3)`` a TDOA's second anchor a_b (zero elsewhere).
        own_sign: ``(N, L)`` the sign of ∂h/∂p_i of a vector channel (GPS +1, landmark and relative −1).
        peer: ``(N, L)`` the neighbour's index of a peer channel (0 elsewhere, masked by ``link``).
        link: ``(N, L, N)`` one-hot: channel l of UAV i measures neighbour j.
    """

    def __init__(self, kind: np.ndarray, target: np.ndarray, sigma: np.ndarray, anchors: np.ndarray,
                 landmarks: np.ndarray) -> None:
        n, n_l = kind.shape
        self.kind = np.asarray(kind, dtype=np.int64)
        self.scalar = np.isin(self.kind, _RANGE_KINDS)
        self.rows = np.ones((n, n_l, 3))
        self.rows[self.scalar, 1:] = 0.0
        self.inv_r = self.rows / (np.asarray(sigma, dtype=np.float64) ** 2)[..., None]
        self.point = np.zeros((n, n_l, 3))
        self.point_b = np.zeros((n, n_l, 3))
        self.own_sign = np.where(self.kind == GPS, 1.0, -1.0)
        self.peer = np.zeros((n, n_l), dtype=np.int64)
        self.link = np.zeros((n, n_l, n))
        for i in range(n):
            for l in range(n_l):
                k, t = int(self.kind[i, l]), int(target[i, l])
                if k == ANCHOR:
                    self.point[i, l] = anchors[t]
                elif k == LANDMARK:
                    self.point[i, l] = landmarks[t]
                elif k == TDOA:
                    a, b = tdoa_pair(t, len(anchors))
                    self.point[i, l], self.point_b[i, l] = anchors[a], anchors[b]
                elif k in _PEER_KINDS:
                    self.peer[i, l] = t
                    self.link[i, l, t] = 1.0


def block_model(dt: float, imu_sigma: float, n_offsets: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The per-axis coefficients (f, q) of the prediction over the block kinds p, v and ``n_offsets``
    accelerometer offsets (the bias b, the fault offset f).

    Returns:
        f ``(k, k)``: x⁻ = F x on every axis, [[1, dt], [0, 1]] (with one offset [[1, dt, −dt²/2],
        [0, 1, −dt], [0, 0, 1]]); q ``(k, k)``: σ_imu² G Gᵀ per axis, 0 on the offsets.
    """
    F, G = transition(dt)
    Q = imu_sigma**2 * G @ G.T
    k = 2 + n_offsets
    f, q = np.eye(k), np.zeros((k, k))
    f[0, 1] = F[0, 3]
    q[:2, :2] = [[Q[0, 0], Q[0, 3]], [Q[3, 0], Q[3, 3]]]
    for o in range(2, k):
        # an offset enters as −o through G: ∂p/∂o = −dt²/2, ∂v/∂o = −dt
        f[0, o], f[1, o] = -G[0, 0], -G[3, 0]
    return f, q


def predict_joint(x: np.ndarray, offsets: np.ndarray | None, P: np.ndarray, imu: np.ndarray, dt: float,
                  imu_sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Propagate the joint state with every UAV's IMU (the module docstring's prediction).

    Args:
        x: ``(B, N, 6)`` mean [p, v] per UAV; offsets: ``(B, N, m, 3)`` the accelerometer offsets' estimates
            (bias, fault offset), or None where the task has none.
        P: ``(B, 3kN, 3kN)`` joint covariance, block kinds p, v and the m offsets, each 3N wide.
        imu: ``(B, N, 3)`` accelerometer readings; dt: step [s]; imu_sigma: σ_imu [m/s²].

    Returns:
        (x⁻, P⁻), new arrays (the offsets are constant).
    """
    F, G = transition(dt)
    # x⁻ = F x + G (u − Σ offsets), UAV by UAV
    x_prior = x @ F.T + (imu if offsets is None else imu - offsets.sum(axis=2)) @ G.T
    f, q = block_model(dt, imu_sigma, 0 if offsets is None else offsets.shape[2])
    k = len(f)
    n_b, n3 = P.shape[0], P.shape[-1] // k
    blocks = P.reshape(n_b, k, n3, k, n3)
    out = np.zeros_like(blocks)
    # P⁻[a, c] = Σ f[a, i] f[c, j] P[i, j] + q[a, c] I over the nonzero coefficients
    nz = [[(i, f[a, i]) for i in range(k) if f[a, i] != 0.0] for a in range(k)]
    for a in range(k):
        for c in range(k):
            for i, fa in nz[a]:
                for j, fc in nz[c]:
                    out[:, a, :, c, :] += (fa * fc) * blocks[:, i, :, j, :]
            if q[a, c] != 0.0:
                out[:, a, np.arange(n3), c, np.arange(n3)] += q[a, c]
    return x_prior, out.reshape(P.shape)


def channel_information(p: np.ndarray, z: np.ndarray, use: np.ndarray,
                        layout: JointLayout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Information of the used channels in the position block: Λ = Σ Hᵀ R⁻¹ H and η = Σ Hᵀ R⁻¹ y.

    Args:
        p: ``(B, N, 3)`` prior positions.
        z: ``(B, N, L, 3)`` measurements (ranges in component 0).
        use: ``(B, N, L)`` bool, the channels that enter.
        layout: the task's ``JointLayout``.

    Returns:
        (Λ ``(B, 3N, 3N)``, η ``(B, 3N)``, used ``(B, N, L)`` bool: ``use`` less degenerate ranges).
    """
    n_b, n, n_l = use.shape
    kind = layout.kind
    # the other end of a range: an anchor, or the neighbour's prior position
    other = np.where((kind == PEER)[None, :, :, None], p[:, layout.peer], layout.point[None])
    d = p[:, :, None, :] - other
    rng = np.linalg.norm(d, axis=-1)
    # TDOA: the second anchor's range, h = ‖p − a_b‖ − ‖p − a_a‖
    d_b = p[:, :, None, :] - layout.point_b[None]
    rng_b = np.linalg.norm(d_b, axis=-1)
    tdoa = (kind == TDOA)[None]
    used = use & ~(layout.scalar[None] & (rng < _MIN_RANGE)) & ~(tdoa & (rng_b < _MIN_RANGE))
    with np.errstate(invalid="ignore", divide="ignore"):
        u = d / rng[..., None]
        u_b = d_b / rng_b[..., None]
    # J: ∂h/∂p_i, one row (a range: uᵀ; TDOA: u_bᵀ − u_aᵀ) or three (±I); y = z − h(x⁻)
    J = np.zeros((n_b, n, n_l, 3, 3))
    y = np.zeros((n_b, n, n_l, 3))
    scalar = layout.scalar[None]
    J[..., 0, :] = np.where(tdoa[..., None], u_b - u, u)
    y[..., 0] = z[..., 0] - np.where(tdoa, rng_b - rng, rng)
    vec = ~scalar
    J_vec = layout.own_sign[None, :, :, None, None] * np.eye(3)
    # GPS: h = p; landmark: h = m − p; relative position: h = p_j − p
    target_pos = np.where((kind == PEER_REL)[None, :, :, None], p[:, layout.peer], layout.point[None])
    p_own = p[:, :, None, :]
    h_vec = np.where((kind == GPS)[None, :, :, None], p_own, target_pos - p_own)
    J = np.where(vec[..., None, None], J_vec, J)
    y = np.where(vec[..., None], z - h_vec, y)
    w = np.where(used[..., None], layout.inv_r[None], 0.0)
    J = np.where(used[..., None, None], J, 0.0)  # a skipped channel's NaN direction must not reach a sum
    y = np.where(used[..., None], y, 0.0)
    # per channel: Hᵢᵀ R⁻¹ Hᵢ and Hᵢᵀ R⁻¹ y in UAV i's block; ∂h/∂p_j = −∂h/∂p_i for both peer kinds
    info = np.einsum("bnlrx,bnlr,bnlry->bnlxy", J, w, J)
    grad = np.einsum("bnlrx,bnlr,bnlr->bnlx", J, w, y)
    cross = np.einsum("ilj,bilxy->bijxy", layout.link, info)  # Σ over i's channels to j
    blocks = -cross - cross.transpose(0, 2, 1, 4, 3)
    diag = info.sum(axis=2) + cross.sum(axis=1)
    idx = np.arange(n)
    blocks[:, idx, idx] += diag
    eta = grad.sum(axis=2) - np.einsum("ilj,bilx->bjx", layout.link, grad)
    Lam = blocks.transpose(0, 1, 3, 2, 4).reshape(n_b, 3 * n, 3 * n)
    return Lam, eta.reshape(n_b, 3 * n), used


def update_joint(x: np.ndarray, P: np.ndarray, Lam: np.ndarray, eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The joint EKF update from the channels' information (the module docstring's update).

    Args:
        x: ``(B, N, 3k)`` prior mean per UAV, [p, v] (k = 2) or [p, v, b] (k = 3); P: ``(B, 3kN, 3kN)``
            prior covariance, block kinds p, v (, b), positions first.
        Lam: ``(B, 3N, 3N)`` Σ Hᵀ R⁻¹ H; eta: ``(B, 3N)`` Σ Hᵀ R⁻¹ y, both at the prior.

    Returns:
        (x⁺, P⁺), new arrays.
    """
    n_b, n, width = x.shape
    k = width // 3
    n3 = 3 * n
    A = P[:, :n3, :n3]
    Pp = P[:, :, :n3]
    # W = (I + Λ A)⁻¹, M = W Λ (= Hᵀ S⁻¹ H, S = H A Hᵀ + R)
    W = np.linalg.inv(np.eye(n3) + Lam @ A)
    M = W @ Lam
    # x⁺ = x⁻ + K y = x⁻ + P_·p W η
    dx = (Pp @ (W @ eta[..., None]))[..., 0]
    # per UAV [p, v (, b)] ↔ the blocks p_1 … p_N, v_1 … v_N (, b_1 … b_N)
    flat = x.reshape(n_b, n, k, 3).transpose(0, 2, 1, 3).reshape(n_b, k * n3) + dx
    x_post = flat.reshape(n_b, k, n, 3).transpose(0, 2, 1, 3).reshape(n_b, n, width)
    # P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ = P + P_·p (M A Mᵀ + W Λ Wᵀ − M − Mᵀ) P_·pᵀ  (Joseph form)
    Mt = M.transpose(0, 2, 1)
    D = M @ A @ Mt + W @ Lam @ W.transpose(0, 2, 1) - M - Mt
    P_post = P + Pp @ D @ Pp.transpose(0, 2, 1)
    # symmetrize: the products above round differently on either side of the diagonal
    P_post = 0.5 * (P_post + P_post.transpose(0, 2, 1))
    return x_post, P_post


def joint_flops(n_uav: int, n_offsets: int = 0) -> float:
    """FLOPs of one step of the joint filter for the whole swarm (the module docstring's count)."""
    n3, k = 3 * n_uav, 2 + n_offsets
    nnz = 3 + 3 * n_offsets
    predict = 2 * nnz * nnz * n3 * n3 + 3 * n3 + 6 * 3 * n_uav
    update = 8 * n3**3 + 2 * (k * n3) * n3 * n3 + 2 * (k * n3) ** 2 * n3
    return float(predict + update)


class CentralizedOracle:
    """One EKF over the swarm's joint state, with the error-labelled channels left out (privileged).

    The runner hands the pending step's labels to ``observe_privileged`` before every ``step``;
    ``step`` refuses to run without them, and uses them for that step only.
    """

    privileged = True
    deterministic = True

    def __init__(self) -> None:
        self._facts: TaskFacts | None = None
        self._labels: np.ndarray | None = None

    def reset(self, facts: TaskFacts, x0: np.ndarray) -> None:
        """Start B episodes at the prior ``x0`` ``(B, N, 6)`` with the CEKF's initial covariance, uncorrelated."""
        x, P_uav = cekf_prior(facts, x0)
        n_b, n = facts.batch_size, facts.n_uav
        n3 = 3 * n
        with_bias = facts.imu_bias_sigma > 0.0
        # the offsets' block kinds after p, v: the bias (prior mean 0) where the task draws one, then the fault
        # offset where it injects IMU faults (0 and certain until a window opens)
        self.fault_block = 2 + with_bias if facts.imu_faults else None
        n_off = int(with_bias) + int(facts.imu_faults)
        k = 2 + n_off
        self.x = np.concatenate([x, np.zeros((n_b, n, 3 * n_off))], axis=2)
        # P0: every UAV's CEKF prior on the diagonal blocks, positions first; σ_b² I on the bias, uncorrelated
        P = np.zeros((n_b, k * n3, k * n3))
        for i in range(n):
            for a in range(2):
                for c in range(2):
                    P[:, a * n3 + 3 * i:a * n3 + 3 * i + 3, c * n3 + 3 * i:c * n3 + 3 * i + 3] = \
                        P_uav[:, i, 3 * a:3 * a + 3, 3 * c:3 * c + 3]
        if with_bias:
            idx = np.arange(2 * n3, 3 * n3)
            P[:, idx, idx] = facts.imu_bias_sigma**2
        self.P = P
        self.fault_variance = np.zeros((n_b, n))
        self.layout = JointLayout(facts.kind, facts.target, facts.sigma, facts.anchors, facts.landmarks)
        self._facts = facts
        self._labels = None
        self._fault: np.ndarray | None = None
        self._flops = np.full((n_b, n), joint_flops(n, n_off) / n)

    def observe_privileged(self, info: PrivilegedInfo) -> None:
        """Receive the pending measurements' error labels ``(B, N, L)`` (the channels to leave out)."""
        if self._facts is None:
            raise RuntimeError("call reset(facts, x0) before observe_privileged()")
        if info.error_labels is None:
            raise ValueError("centralized-oracle reads PrivilegedInfo.error_labels, which was not provided")
        labels = np.asarray(info.error_labels, dtype=bool)
        shape = (self._facts.batch_size, self._facts.n_uav, self._facts.n_channels)
        if labels.shape != shape:
            raise ValueError(f"error_labels must have shape (B, N, L) = {shape}, got {labels.shape}")
        self._labels = labels.copy()
        if self.fault_block is not None:
            if info.imu_fault_variance is None:
                raise ValueError("centralized-oracle on a task with IMU faults reads PrivilegedInfo.imu_fault_variance, "
                                 "which was not provided")
            fault = np.asarray(info.imu_fault_variance, dtype=np.float64)
            if fault.shape != shape[:2]:
                raise ValueError(f"imu_fault_variance must have shape (B, N) = {shape[:2]}, got {fault.shape}")
            self._fault = fault.copy()

    def step(self, meas: Measurements) -> EstimatorOutput:
        """Predict the joint state with the IMU, update with every unlabelled valid channel.

        Returns:
            Positions, position covariances (the diagonal blocks of P), the trust applied
            (0 on a labelled channel, 1 elsewhere) and FLOPs.

        Raises:
            RuntimeError: no labels for this step (not run as a privileged method).
        """
        f = self._facts
        if f is None:
            raise RuntimeError("call reset(facts, x0) before step()")
        if self._labels is None:
            raise RuntimeError("centralized-oracle needs observe_privileged(info) before every step(); "
                               "run it through the swarmloc runner, which passes labels to privileged methods")
        labels, self._labels = self._labels, None
        if self.fault_block is not None:
            self._open_and_close_faults(self._fault)
        imu = np.asarray(meas.imu, dtype=np.float64)
        n_b, n, width = self.x.shape
        if width > 6:
            offsets = self.x[..., 6:].reshape(n_b, n, width // 3 - 2, 3)
            pv, P = predict_joint(self.x[..., :6], offsets, self.P, imu, f.dt, f.imu_sigma)
            self.x, self.P = np.concatenate([pv, self.x[..., 6:]], axis=2), P
        else:
            self.x, self.P = predict_joint(self.x, None, self.P, imu, f.dt, f.imu_sigma)
        use = np.asarray(meas.valid, dtype=bool) & ~labels
        Lam, eta, _ = channel_information(self.x[..., :3], np.asarray(meas.z, dtype=np.float64), use, self.layout)
        self.x, self.P = update_joint(self.x, self.P, Lam, eta)
        return EstimatorOutput(positions=self.x[..., :3].copy(), cov=self.position_cov(),
                               weights=np.where(labels, 0.0, 1.0), flops=self._flops.copy())

    def _open_and_close_faults(self, variance: np.ndarray) -> None:
        """Apply the fault windows of the coming step (``variance`` ``(B, N)`` σ_f² per UAV) to the fault offsets.

        Where σ_f² rose (a window opened) the offset gets that much more prior variance, independent of the
        rest; where it fell (a window closed) the offset is 0 and certain again at the new σ_f² (0 when no
        other window of the UAV stays open: overlapping windows are rare, and a closing one's share of the
        estimate cannot be told apart)."""
        n3 = 3 * variance.shape[1]
        base = self.fault_block * n3
        rose = variance > self.fault_variance
        fell = variance < self.fault_variance
        for b, i in zip(*np.nonzero(fell)):
            idx = base + 3 * i + np.arange(3)
            self.x[b, i, 3 * self.fault_block:3 * self.fault_block + 3] = 0.0
            self.P[b, idx, :] = 0.0
            self.P[b, :, idx] = 0.0
            self.P[b, idx, idx] = variance[b, i]
        for b, i in zip(*np.nonzero(rose)):
            idx = base + 3 * i + np.arange(3)
            self.P[b, idx, idx] += variance[b, i] - self.fault_variance[b, i]
        self.fault_variance = variance

    def position_cov(self) -> np.ndarray:
        """``(B, N, 3, 3)`` each UAV's position covariance (the diagonal 3 × 3 blocks of P's position block)."""
        n_b, n = self.x.shape[:2]
        idx = np.arange(n)
        blocks = self.P[:, :3 * n, :3 * n].reshape(n_b, n, 3, n, 3)
        return blocks[:, idx, :, idx, :].transpose(1, 0, 2, 3).copy()


def centralized_oracle() -> CentralizedOracle:
    """Registry factory: ``centralized-oracle``."""
    return CentralizedOracle()
