"""The classical frontier: CUSUM and RAIM link trust, and the peer NIS with the neighbour's covariance (v1)."""

from __future__ import annotations

import numpy as np
import pytest
from trust_helpers import trust_input as _input
from trust_helpers import trust_layout as _layout

from swarmloc.agents.trust.integrity import CusumTrust, RaimTrust, admissible, cusum_step
from swarmloc.agents.protocols import episode_keys
from swarmloc.agents.registry import REGISTRY, LoadedMethod, load_method
from swarmloc.agents.estimators.trust_estimator import TrustEstimator
from swarmloc.bench.evaluation.runner import evaluate_task, rollout
from swarmloc.bench.speed.world import UnfusedCore
from swarmloc.envs.tasks.channels import ANCHOR, LANDMARK, PEER, PEER_REL
from swarmloc.envs.world.core import LinkTrustCore
from swarmloc.envs.tasks.catalogue import get_spec

SEEDS = list(range(1_000_000, 1_000_012))


# --------------------------------------------------------------------------- CUSUM


def _cusum_reference(x: np.ndarray, reference: float, h: float) -> np.ndarray:
    """A readable scalar CUSUM: Page's g⁺ while trusted, the reverse g⁻ while alarmed. Returns the alarm per step."""
    g_up = g_down = 0.0
    alarmed = False
    out = np.zeros(len(x), dtype=bool)
    for k, xk in enumerate(x):
        if not alarmed:
            g_up = max(0.0, g_up + xk - reference)
            if g_up > h:
                alarmed, g_down = True, 0.0
        else:
            g_down = max(0.0, g_down + reference - xk)
            if g_down > h:
                alarmed, g_up = False, 0.0
        out[k] = alarmed
    return out


def test_cusum_constants_follow_from_the_design_point():
    c = CusumTrust(4.0, 1e4)
    # κ = λ ln λ / (λ − 1), h = 2 ln(ARL₀) λ / (λ − 1)
    assert c.drift == pytest.approx(4 * np.log(4) / 3)
    assert c.threshold == pytest.approx(2 * np.log(1e4) * 4 / 3)
    assert (round(c.drift, 3), round(c.threshold, 2)) == (1.848, 24.56)
    with pytest.raises(ValueError, match="design_ratio must be > 1"):
        CusumTrust(1.0)
    with pytest.raises(ValueError, match="arl must be > 1"):
        CusumTrust(4.0, 0.5)


def test_cusum_policy_equals_the_readable_reference_and_detects_after_the_expected_delay():
    """Ten ranges, one with a step bias (E NIS = 4, the design point) between steps 200 and 400."""
    rng = np.random.default_rng(7)
    n_t, n_l, biased = 700, 10, 3
    noise = rng.standard_normal((n_t, n_l))
    noise[200:400, biased] += np.sqrt(3.0)  # E (n + √3)² = 4
    nis = noise**2
    pol = CusumTrust()
    pol.reset(1, _layout([ANCHOR] * n_l), episode_keys([0]))
    trust = np.array([pol.act(_input(nis[k][None, None, :], step=k + 1))[0, 0] for k in range(n_t)])
    for l in range(n_l):
        expected = _cusum_reference(nis[:, l], pol.drift, pol.threshold)
        np.testing.assert_array_equal(trust[:, l] < 1.0, expected, err_msg=f"channel {l}")
    alarm = trust[:, biased] < 1.0
    onset = int(np.argmax(alarm[200:]))
    # Wald: h / (E x − κ) = 24.56 / 2.15 ≈ 11 steps (plus the overshoot)
    assert 3 <= onset <= 30
    readmit = int(np.argmax(~alarm[400:]))
    # h / (κ − 1) ≈ 29 steps of health evidence
    assert 10 <= readmit <= 60
    assert not alarm[400 + readmit:].any()  # stays readmitted on clean data here


def test_cusum_delays_match_wald_on_average():
    """Mean detection delay at the design point and mean readmission time, over many channels at once."""
    rng = np.random.default_rng(11)
    n = 4000
    c = CusumTrust()
    shape = (n,)
    g_up, g_down, alarm = np.zeros(shape), np.zeros(shape), np.zeros(shape, bool)
    first = np.full(n, -1)
    for k in range(200):
        x = (rng.standard_normal(n) + np.sqrt(3.0)) ** 2
        g_up, g_down, alarm = cusum_step(g_up, g_down, alarm, x, np.ones(shape, bool), c.drift, c.threshold)
        first[(first < 0) & alarm] = k + 1
    assert (first > 0).all()
    wald = c.threshold / (4.0 - c.drift)
    assert 0.8 * wald <= first.mean() <= 1.3 * wald  # the overshoot adds a little
    back = np.full(n, -1)
    for k in range(300):
        x = rng.standard_normal(n) ** 2
        g_up, g_down, alarm = cusum_step(g_up, g_down, alarm, x, np.ones(shape, bool), c.drift, c.threshold)
        back[(back < 0) & ~alarm] = k + 1
    assert (back > 0).all()
    # (the health statistic may already be above 0 when the bias ends)
    wald_back = c.threshold / (c.drift - 1.0)
    assert 0.8 * wald_back <= back.mean() <= 1.3 * wald_back


def test_cusum_stays_quiet_on_nominal_noise():
    """False alarms on healthy χ²(1) and χ²(3) channels: at most the stated 1/ARL₀ per step (Lorden's bound)."""
    rng = np.random.default_rng(3)
    c = CusumTrust()
    n, n_t = 1000, 20_000
    for d in (1, 3):
        g = np.zeros(n)
        first = np.full(n, n_t)
        for k in range(n_t):
            g = np.maximum(0.0, g + rng.chisquare(d, n) - c.drift * d)
            hit = (g > c.threshold) & (first == n_t)
            first[hit] = k + 1
        rate = (first < n_t).sum() / first.sum()
        # the bound ARL₀ ≥ e^{h_LLR} = 10⁴ is conservative: the simulated rate is about 10× lower
        assert rate <= 1.0 / c.arl, (d, rate)
        assert rate >= 1.0 / (100 * c.arl), (d, rate)


def test_cusum_keeps_state_for_absent_channels_and_resets():
    pol = CusumTrust()
    pol.reset(1, _layout([ANCHOR] * 5), episode_keys([0]))
    big = np.array([[[100.0, 0.5, 0.5, 0.5, 0.5]]])
    assert pol.act(_input(big))[0, 0, 0] == 0.01  # one step above h + κ: at once
    absent = np.array([[[False, True, True, True, True]]])
    for k in range(100):  # absent: no evidence either way, stays distrusted
        pol.act(_input(np.array([[[0.0, 0.5, 0.5, 0.5, 0.5]]]), absent, step=k + 2))
    assert pol.alarm[0, 0, 0]
    pol.reset(1, _layout([ANCHOR] * 5), episode_keys([0]))
    assert not pol.alarm.any()


def test_cusum_attributes_a_majority_of_alarms_to_the_prior():
    """Every channel of a UAV alarmed at once: its prior drifted; all trusted and the statistics restart."""
    pol = CusumTrust()
    pol.reset(1, _layout([ANCHOR] * 3 + [PEER] * 3), episode_keys([0]))
    alpha = pol.act(_input(np.full((1, 1, 6), 500.0)))
    np.testing.assert_array_equal(alpha, 1.0)
    assert not pol.alarm.any()


# --------------------------------------------------------------------------- RAIM


def _static_nis(bias: dict[int, float]) -> np.ndarray:
    """NIS of 8 anchor ranges to a static UAV (prior at the truth, σ_p = 0.1 m, σ = 0.15 m), some biased."""
    rng = np.random.default_rng(5)
    anchors = np.array([[-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0],
                        [-10, -10, 5], [10, -10, 5], [10, 10, 5], [-10, 10, 5]], float)
    p, P, sigma = np.array([1.0, 2.0, 1.5]), 0.1**2 * np.eye(3), 0.15
    nis = np.empty(len(anchors))
    for j, a in enumerate(anchors):
        u = (p - a) / np.linalg.norm(p - a)
        # y = z − h(x⁻) with z = ‖p − a‖ + b + σ n; S = uᵀ P u + σ²
        y = bias.get(j, 0.0) + sigma * rng.standard_normal()
        nis[j] = y * y / (u @ P @ u + sigma**2)
    return nis[None, None, :]


def test_raim_excludes_nothing_on_clean_data():
    pol = RaimTrust()
    pol.reset(1, _layout([ANCHOR] * 8), episode_keys([0]))
    np.testing.assert_array_equal(pol.act(_input(_static_nis({}))), 1.0)


def test_raim_excludes_the_one_biased_channel():
    pol = RaimTrust()
    pol.reset(1, _layout([ANCHOR] * 8), episode_keys([0]))
    alpha = pol.act(_input(_static_nis({5: 1.0})))
    expected = np.ones((1, 1, 8))
    expected[0, 0, 5] = 0.01
    np.testing.assert_array_equal(alpha, expected)


def test_raim_excludes_several_faults_up_to_a_minority():
    pol = RaimTrust()
    pol.reset(1, _layout([ANCHOR] * 8), episode_keys([0]))
    alpha = pol.act(_input(_static_nis({1: 1.5, 6: 2.0})))
    assert set(np.nonzero(alpha[0, 0] < 1.0)[0]) == {1, 6}
    # the sum dilutes: once the 2 m channel is out, a 1 m bias (NIS 19.8 with this noise) hides among
    # seven channels (Σ 21.7 < χ²₀.₉₉₉(7) = 24.3), where a per-channel gate would catch it
    alpha = pol.act(_input(_static_nis({1: 1.0, 6: 2.0})))
    assert set(np.nonzero(alpha[0, 0] < 1.0)[0]) == {6}
    # five of eight anchors biased: no admissible exclusion explains it, the prior is suspected: trust all
    alpha = pol.act(_input(_static_nis({0: 2.0, 1: 2.5, 2: 3.0, 3: 3.5, 4: 4.0})))
    np.testing.assert_array_equal(alpha, 1.0)


def test_raim_leave_one_out_compares_channels_of_different_rows():
    """A 3-row landmark with NIS 30 is a smaller outlier than a range with NIS 25 (χ²₀.₉₉₉: 16.3 vs 10.8)."""
    pol = RaimTrust()
    pol.reset(1, _layout([ANCHOR] * 4 + [LANDMARK]), episode_keys([0]))
    alpha = pol.act(_input(np.array([[[0.5, 25.0, 1.0, 0.2, 30.0]]])))
    # without the range: (0.5 + 1 + 0.2 + 30) / χ²(6) = 1.41; without the landmark: 26.7 / χ²(4) = 1.45
    assert alpha[0, 0, 1] == 0.01
    assert (alpha[0, 0, [0, 2, 3]] == 1.0).all()


def test_the_peer_group_is_one_witness_and_a_fix_needs_three_rows():
    is_peer = np.array([[False] * 2 + [True] * 5])
    dof = np.ones((1, 7), dtype=np.int64)
    valid = np.ones((1, 1, 7), bool)
    # both absolute channels against five agreeing peers: 2 claimed faults against prior + peer group = 2: a tie
    assert not admissible(np.array([[[True, True] + [False] * 5]]), valid, dof, is_peer)[0, 0]
    # one absolute channel out: 1 < 1 + 1 + 1
    assert admissible(np.array([[[True, False] + [False] * 5]]), valid, dof, is_peer)[0, 0]
    # three of five peers out (the group) with both absolute channels backing the prior: 1 < 1 + 2
    assert admissible(np.array([[[False, False, True, True, True, False, False]]]), valid, dof, is_peer)[0, 0]
    # a lone GPS against one peer range: excluding the GPS would leave a single row
    assert not admissible(np.array([[[True, False]]]), np.ones((1, 1, 2), bool), np.array([[3, 1]]),
                          np.array([[False, True]]))[0, 0]


# --------------------------------------------------------------------------- on a task


def test_registered_and_deterministic():
    for name in ("cusum", "raim"):
        entry = REGISTRY[name]
        loaded = load_method(name)
        assert (entry.track, entry.privileged, loaded.track, loaded.privileged) == ("A", False, "A", False)
    assert load_method("cusum+smooth").track == "A"


@pytest.fixture(scope="module")
def cascaded() -> dict:
    return evaluate_task(["chi2-gate", "cusum", "raim"], "swarmloc/CascadedFaultRandom-v1", SEEDS).episodes


def test_faulty_nodes_recover_with_cusum_and_raim_but_not_chi2_gate(cascaded):
    """chi2-gate locks every drifted node out; cusum and raim re-acquire (not on every episode: see docs/methods.md)."""
    assert all(e["recovered"] == 0.0 for e in cascaded["chi2-gate"])
    for name in ("cusum", "raim"):
        recovered = [e for e in cascaded[name] if e["recovered"] == 1.0]
        assert len(recovered) >= 2, name
        gate = {s: e["recovery_s"] for s, e in zip(SEEDS, cascaded["chi2-gate"])}
        for seed, e in zip(SEEDS, cascaded[name]):
            if e["recovered"] == 1.0:
                assert np.isfinite(e["recovery_s"]) and e["recovery_s"] < gate[seed]


# --------------------------------------------------------------------------- peer NIS


def _hand_nis(core: LinkTrustCore, with_neighbour: bool) -> np.ndarray:
    """The pending NIS of every peer channel from the core's priors, by the formulas of docs/world.md."""
    lay, buf = core.layout, core.world.buffers
    out = np.full(core.pending_error_label.shape, np.nan)
    for b in range(core.batch_size):
        for i in range(core.n_uav):
            for l in range(core.n_channels):
                kind, j = lay.kind[i, l], lay.target[i, l]
                if kind not in (PEER, PEER_REL) or not buf.valid[b, i, l]:
                    continue
                p, P_i, P_j = core.x[b, i, :3], core.P[b, i, :3, :3], core.P[b, j, :3, :3]
                q = core.x[b, j, :3]  # the neighbour's broadcast prior
                r0 = lay.sigma[i, l] ** 2
                if kind == PEER:
                    u = (p - q) / np.linalg.norm(p - q)
                    # S = uᵀ P_i u (+ uᵀ P_j u) + R0, y = z − ‖p − p̂_j‖
                    s = u @ P_i @ u + (u @ P_j @ u if with_neighbour else 0.0) + r0
                    out[b, i, l] = (buf.z[b, i, l, 0] - np.linalg.norm(p - q)) ** 2 / s
                else:
                    # S = P_i (+ P_j) + R0 I, y = z − (p̂_j − p)
                    S = P_i + (P_j if with_neighbour else 0.0) + r0 * np.eye(3)
                    y = buf.z[b, i, l] - (q - p)
                    out[b, i, l] = y @ np.linalg.solve(S, y)
    return out


@pytest.mark.parametrize("task_id", ["swarmloc/NLOS-v1", "swarmloc/GradualFault-v1", "swarmloc/NLOS-v0",
                                     "swarmloc/GradualFault-v0"])
def test_peer_nis_includes_the_neighbour_covariance_on_v1_only(task_id):
    spec = get_spec(task_id, duration=20.0 if "Gradual" in task_id else 3.0)
    v1 = spec.version >= 1
    assert spec.peer_nis_neighbour_cov == v1
    core = LinkTrustCore(spec, 2)
    out = core.reset([5, 1_000_001])
    rng = np.random.default_rng(0)
    for _ in range(spec.n_steps // 2):
        out = core.step(rng.uniform(0.3, 1.0, (2, spec.n_uav, spec.n_channels)))
    hand = _hand_nis(core, with_neighbour=v1)
    peer = ~np.isnan(hand)
    assert peer.any()
    np.testing.assert_allclose(out.nis[peer], hand[peer], rtol=1e-9)
    # the other formula differs: the neighbour's covariance matters
    other = _hand_nis(core, with_neighbour=not v1)
    assert not np.allclose(out.nis[peer], other[peer], rtol=1e-6)


@pytest.mark.parametrize("task_id", ["swarmloc/NLOS-v1", "swarmloc/GradualFault-v1"])
def test_v1_peer_nis_is_the_same_on_every_path(task_id):
    """The fused core, the separate batch kernels and TrustEstimator (Track B) share the v1 definition."""
    spec = get_spec(task_id, duration=20.0 if "Gradual" in task_id else 3.0)
    seeds = [5, 1_000_001]
    fused, unfused = LinkTrustCore(spec, 2), UnfusedCore(spec, 2)
    a, b = fused.reset(seeds), unfused.reset(seeds)
    rng = np.random.default_rng(1)
    for _ in range(spec.n_steps - 1):
        assert np.array_equal(a.nis, b["nis"])
        trust = rng.uniform(0.0, 1.0, (2, spec.n_uav, spec.n_channels))
        a, b = fused.step(trust), unfused.step(trust)
    core, _ = rollout(load_method("raim"), spec, seeds)
    method = load_method("raim")
    est = LoadedMethod(name="raim", entry_point="test", track="B", privileged=False, deterministic=True,
                       method=TrustEstimator(method.method))
    track_b, _ = rollout(est, spec, seeds)
    for x, y in zip(core, track_b):
        assert x["rmse"] == pytest.approx(y["rmse"], rel=1e-12)


def test_v0_observation_is_unchanged():
    """NLOS-v0's pending NIS at a fixed step, pinned before the v1 definition existed (bit for bit)."""
    spec = get_spec("swarmloc/NLOS-v0", duration=5.0)
    core = LinkTrustCore(spec, 1)
    out = core.reset([1_000_000])
    for _ in range(20):
        out = core.step(np.ones((1, spec.n_uav, spec.n_channels)))
    assert out.nis[0, 1].tolist() == PINNED_NLOS_V0_NIS


#: ``LinkTrustCore`` on NLOS-v0, seed 1_000_000, 20 updates at α = 1: UAV 1's pending NIS (8 anchors, 3 peers),
#: computed with the code before the v1 peer NIS existed
PINNED_NLOS_V0_NIS: list[float] = [
    0.389176918715165, 0.5772253872206023, 9.339256873359465, 0.8364145732838232, 0.5933015375355147,
    0.33307228618064033, 0.6417478800422246, 0.6114996129991755, 1.215738106330728, 0.5217095190296333,
    6.8414904615396095,
]


@pytest.mark.parametrize("update", ["ci", "split_ci"])
def test_every_path_runs_the_tasks_peer_update(update):
    """TrustEstimator (Track B) and the separate batch kernels run the task's peer update, as the fused core does:
    the same trust gives the same episodes (a path that fell back to ``"point"`` would differ at the first peer)."""
    spec = get_spec("swarmloc/NLOS-v1", duration=4.0, filter={"peer_update": update})
    seeds = [5, 1_000_001]
    fused, unfused = LinkTrustCore(spec, 2), UnfusedCore(spec, 2)
    fused.reset(seeds), unfused.reset(seeds)
    rng = np.random.default_rng(2)
    for _ in range(spec.n_steps - 1):
        trust = rng.uniform(0.0, 1.0, (2, spec.n_uav, spec.n_channels))
        a, b = fused.step(trust), unfused.step(trust)
        np.testing.assert_allclose(a.estimate, b["estimate"], rtol=0, atol=1e-9)
    core, _ = rollout(load_method("raim"), spec, seeds)
    est = LoadedMethod(name="raim", entry_point="test", track="B", privileged=False, deterministic=True,
                       method=TrustEstimator(load_method("raim").method))
    track_b, _ = rollout(est, spec, seeds)
    point, _ = rollout(load_method("raim"), get_spec("swarmloc/NLOS-v1", duration=4.0), seeds)
    for x, y, p in zip(core, track_b, point):
        assert x["rmse"] == pytest.approx(y["rmse"], rel=1e-9)
        assert x["rmse"] != pytest.approx(p["rmse"], rel=1e-6)
