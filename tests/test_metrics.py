"""Each metric against a hand-computed case; the streaming trust sums equal the pure functions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmloc.bench.scoring import metrics as M
ERRORS = np.array([0.0, 1.0, 2.0, 3.0, 4.0])


def test_position_errors():
    est = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    truth = np.array([[3.0, 4.0, 0.0], [1.0, 1.0, 3.0]])
    np.testing.assert_allclose(M.position_errors(est, truth), [5.0, 2.0])


def test_error_statistics_hand_computed():
    # rmse = sqrt((0 + 1 + 4 + 9 + 16) / 5) = sqrt(6)
    assert M.rmse(ERRORS) == pytest.approx(math.sqrt(6.0))
    assert M.mean_error(ERRORS) == pytest.approx(2.0)
    assert M.median_error(ERRORS) == pytest.approx(2.0)
    assert M.max_error(ERRORS) == pytest.approx(4.0)
    # 90th percentile, linear: position 0.9·4 = 3.6 → 3 + 0.6·(4 − 3)
    assert M.cep90(ERRORS) == pytest.approx(3.6)
    # any shape is flattened
    assert M.rmse(ERRORS.reshape(5, 1)) == pytest.approx(math.sqrt(6.0))


def test_empty_errors_rejected():
    with pytest.raises(ValueError, match="no error samples"):
        M.rmse(np.zeros((0, 3)))


def test_window_steps_half_open_and_rounding_safe():
    times = 0.1 * np.arange(1, 11)  # 0.1 … 1.0 with float rounding
    mask = M.window_steps(times, (0.3, 0.6))
    assert mask.tolist() == [False, False, True, True, True, False, False, False, False, False]
    assert not M.window_steps(times, None).any()


def test_fault_rmse():
    errors = np.array([[1.0, 1.0], [3.0, 4.0], [0.0, 0.0]])  # (T=3, N=2)
    # steps 1 only: sqrt((9 + 16) / 2)
    assert M.fault_rmse(errors, np.array([False, True, False])) == pytest.approx(math.sqrt(12.5))
    assert M.fault_rmse(errors, np.zeros(3, dtype=bool)) is None


def test_healthy_rmse():
    errors = np.array([[1.0, 10.0, 3.0], [1.0, 20.0, 3.0]])  # (T=2, N=3); node 1 faulty
    healthy = np.array([True, False, True])
    # sqrt((1 + 9 + 1 + 9) / 4) = sqrt(5)
    assert M.healthy_rmse(errors, healthy, np.array([True, True])) == pytest.approx(math.sqrt(5.0))
    assert M.healthy_rmse(errors, healthy, np.array([True, False])) == pytest.approx(math.sqrt(5.0))
    assert M.healthy_rmse(errors, np.zeros(3, dtype=bool), np.array([True, True])) is None


def test_diverged():
    assert M.diverged(np.array([1.0, 9.9])) == 0.0
    assert M.diverged(np.array([1.0, 10.5])) == 1.0
    assert M.diverged(np.array([1.0, np.inf])) == 1.0


def test_jitter_weight_var_detection():
    applied = np.array([[1.0, 0.5], [0.5, 0.5]])
    previous = np.array([[1.0, 1.0], [1.0, 0.5]])
    valid = np.ones((2, 2), dtype=bool)
    # |Δα| = 0, 0.5, 0.5, 0 → mean 0.25
    assert M.jitter(applied, previous, valid) == pytest.approx(0.25)
    # only the first row valid: (0 + 0.5) / 2
    assert M.jitter(applied, previous, np.array([[True, True], [False, False]])) == pytest.approx(0.25)
    assert M.jitter(applied, previous, np.zeros((2, 2), dtype=bool)) is None
    # values 1, .5, .5, .5: mean .625, var = (.375² + 3·.125²) / 4
    assert M.weight_var(applied, valid) == pytest.approx((0.375**2 + 3 * 0.125**2) / 4)
    assert M.weight_var(np.array([0.0, 1.0]), np.array([True, True])) == pytest.approx(0.25)
    # labelled: α = 0.01 (detected), 0.9 (missed); the unlabelled 0.3 does not count
    rate = M.anomaly_detection_rate(np.array([0.01, 0.9, 0.3]), np.array([True, True, False]))
    assert rate == pytest.approx(0.5)
    assert M.anomaly_detection_rate(np.array([0.4, 0.5]), np.array([True, True])) == pytest.approx(0.5)
    assert M.anomaly_detection_rate(np.array([0.1]), np.array([False])) is None


def test_team_return():
    assert M.team_return(np.array([0.5, 0.25, -1.0])) == pytest.approx(-0.25)
    assert not hasattr(M, "normalized_score")  # the v0 score is retired


def test_channel_stats_equal_pure_functions():
    rng = np.random.default_rng(0)
    n_t, n_b, n, n_l = 6, 3, 4, 5
    applied = rng.uniform(size=(n_t, n_b, n, n_l))
    previous = np.concatenate([np.ones((1, n_b, n, n_l)), applied[:-1]])
    valid = rng.uniform(size=applied.shape) < 0.7
    label = (rng.uniform(size=applied.shape) < 0.3) & valid
    nodes = np.array([True, False, True, True])
    stats = M.ChannelStats(n_b, nodes)
    for k in range(n_t):
        stats.add(applied[k], previous[k], valid[k], label[k])
    for b in range(n_b):
        a, p = applied[:, b][:, nodes], previous[:, b][:, nodes]
        v, lab = valid[:, b][:, nodes], label[:, b][:, nodes]
        assert stats.jitter(b) == pytest.approx(M.jitter(a, p, v), rel=1e-12)
        assert stats.weight_var(b) == pytest.approx(M.weight_var(a, v), rel=1e-9)
        assert stats.anomaly_detection_rate(b) == pytest.approx(M.anomaly_detection_rate(a, lab), rel=1e-12)


def test_channel_stats_per_episode_nodes_equal_each_episode_alone():
    rng = np.random.default_rng(1)
    n_t, n_b, n, n_l = 6, 4, 4, 5
    applied = rng.uniform(size=(n_t, n_b, n, n_l))
    previous = np.concatenate([np.ones((1, n_b, n, n_l)), applied[:-1]])
    valid = rng.uniform(size=applied.shape) < 0.7
    label = (rng.uniform(size=applied.shape) < 0.3) & valid
    nodes = np.array([[True, False, True, False], [False, True, True, True],
                      [True, False, True, False], [True, True, False, False]])
    batched = M.ChannelStats(n_b, nodes)
    alone = [M.ChannelStats(1, nodes[b]) for b in range(n_b)]
    for k in range(n_t):
        batched.add(applied[k], previous[k], valid[k], label[k])
        for b, one in enumerate(alone):
            one.add(applied[k, b:b + 1], previous[k, b:b + 1], valid[k, b:b + 1], label[k, b:b + 1])
    for b, one in enumerate(alone):  # bit for bit: verification re-runs single episodes
        assert (batched.jitter(b), batched.weight_var(b), batched.anomaly_detection_rate(b)) == \
            (one.jitter(0), one.weight_var(0), one.anomaly_detection_rate(0))
        a, p, v = applied[:, b][:, nodes[b]], previous[:, b][:, nodes[b]], valid[:, b][:, nodes[b]]
        assert batched.jitter(b) == pytest.approx(M.jitter(a, p, v), rel=1e-12)


def _stepwise_sums(applied, previous, valid, label, nodes) -> dict[str, np.ndarray]:
    """The channel sums added one step at a time (a readable reference of ``ChannelStats``)."""
    n_b = applied.shape[1]
    sums = {k: np.zeros(n_b) for k in ("n_valid", "abs_delta", "alpha_sum", "alpha_sq", "n_label", "n_detected")}
    shift = np.full(n_b, np.nan)
    for k in range(applied.shape[0]):
        for b in range(n_b):
            a, p = applied[k, b][nodes[b]].ravel(), previous[k, b][nodes[b]].ravel()
            m, lab = valid[k, b][nodes[b]].ravel(), label[k, b][nodes[b]].ravel() & valid[k, b][nodes[b]].ravel()
            if np.isnan(shift[b]) and m.sum() > 0:
                shift[b] = (a * m).sum() / m.sum()
            d = a - np.nan_to_num(shift[b])
            for name, value in (("n_valid", m.sum()), ("abs_delta", (np.abs(a - p) * m).sum()),
                                ("alpha_sum", (d * m).sum()), ("alpha_sq", (d * d * m).sum()),
                                ("n_label", lab.sum()), ("n_detected", ((a < M.DETECTION_TRUST) & lab).sum())):
                sums[name][b] += value
    return sums


def test_channel_stats_buffered_equal_step_by_step_bit_for_bit(monkeypatch):
    rng = np.random.default_rng(2)
    n_t, n_b, n, n_l = 40, 3, 3, 6
    applied = rng.uniform(size=(n_t, n_b, n, n_l))
    previous = np.concatenate([np.ones((1, n_b, n, n_l)), applied[:-1]])
    valid = rng.uniform(size=applied.shape) < 0.6
    valid[:9, 1] = False  # episode 1 has no valid channel before step 9 (a block boundary below)
    valid[:, 2] = False  # episode 2 never has one
    label = (rng.uniform(size=applied.shape) < 0.3) & valid
    nodes = np.array([[True, False, True], [True, True, True], [True, False, True]])
    monkeypatch.setattr(M.ChannelStats, "BUFFER_VALUES", 7 * 2 * n * n_l)  # blocks of 7 steps for each group
    expected = _stepwise_sums(applied, previous, valid, label, nodes)
    stats = M.ChannelStats(n_b, nodes)
    step = np.empty_like(applied[0])
    for k in range(n_t):
        step[:] = applied[k]  # one array, overwritten every step: what was added must not change
        stats.add(step, previous[k], valid[k], label[k])
    stats._flush()
    for name, values in expected.items():
        assert np.array_equal(getattr(stats, name), values), name
    assert stats.jitter(2) is None and stats.weight_var(2) is None


# --------------------------------------------------------------------------- recovery_s on synthetic traces

DT = 0.1
TIMES = DT * np.arange(1, 101)  # t = 0.1 … 10 s
FAULT_END = 3.0                  # step 30 (index 29) is the first at the fault end


def _trace(*segments: tuple[float, float, float]) -> np.ndarray:
    """An error trace of ``TIMES``: ``(t0, t1, value)`` segments on [t0, t1), 0.5 m elsewhere."""
    e = np.full(TIMES.shape, 0.5)
    for t0, t1, value in segments:
        e[(TIMES >= t0 - 1e-9) & (TIMES < t1 - 1e-9)] = value
    return e


def test_recovery_time_recovers_at_a_known_step():
    # 20 m until 5.2 s, then back within 1 m: recovered 5.2 − 3.0 = 2.2 s after the fault end
    seconds, recovered = M.recovery_time(_trace((0.0, 5.2, 20.0)), TIMES, FAULT_END, 1.0)
    assert recovered and seconds == pytest.approx(2.2, abs=1e-12)


def test_recovery_time_already_within_at_the_fault_end_is_zero():
    # high during the fault only: the first step at t = 3.0 s is already within
    assert M.recovery_time(_trace((1.0, 3.0, 20.0)), TIMES, FAULT_END, 1.0) == (pytest.approx(0.0, abs=1e-12), True)


def test_recovery_time_never_recovers_is_censored_at_the_episode_end():
    seconds, recovered = M.recovery_time(_trace((0.0, 11.0, 20.0)), TIMES, FAULT_END, 1.0)
    assert not recovered and seconds == pytest.approx(10.0 - 3.0, abs=1e-12)
    # a non-finite last error is not "within" either
    seconds, recovered = M.recovery_time(_trace((9.95, 11.0, np.nan)), TIMES, FAULT_END, 1.0)
    assert not recovered and seconds == pytest.approx(7.0, abs=1e-12)


def test_recovery_time_relapse_counts_from_the_last_return():
    # back within at 4 s, relapses on [6, 7.5) s, within again from 7.5 s: recovered 4.5 s after the end
    e = _trace((0.0, 4.0, 20.0), (6.0, 7.5, 3.0))
    seconds, recovered = M.recovery_time(e, TIMES, FAULT_END, 1.0)
    assert recovered and seconds == pytest.approx(4.5, abs=1e-12)
    # and a relapse that lasts to the end is never recovered
    seconds, recovered = M.recovery_time(_trace((0.0, 4.0, 20.0), (6.0, 11.0, 3.0)), TIMES, FAULT_END, 1.0)
    assert not recovered and seconds == pytest.approx(7.0, abs=1e-12)


def test_recovery_time_threshold_is_inclusive_and_undefined_after_the_episode():
    assert M.recovery_time(_trace((0.0, 5.0, 1.0)), TIMES, FAULT_END, 1.0)[0] == pytest.approx(0.0, abs=1e-12)
    assert M.recovery_time(_trace(), TIMES, 10.5, 1.0) is None  # the fault outlasts the episode


def test_recovery_is_the_slowest_faulty_uav_and_threshold_has_a_floor():
    errors = np.stack([_trace((0.0, 4.0, 20.0)),           # faulty, recovers 1.0 s after its end (3 s)
                       _trace((0.0, 11.0, 20.0)),          # healthy (no fault end): ignored
                       _trace((0.0, 7.0, 20.0))], axis=1)  # faulty, its fault ends at 5 s: 2.0 s
    ends = np.array([3.0, np.nan, 5.0])
    assert M.recovery(errors, TIMES, ends, 1.0) == (pytest.approx(2.0, abs=1e-12), 1.0)
    errors[-1, 0] = 20.0  # UAV 0 relapses at the last step: censored at 10 − 3 = 7 s
    assert M.recovery(errors, TIMES, ends, 1.0) == (pytest.approx(7.0, abs=1e-12), 0.0)
    assert M.recovery(errors, TIMES, np.full(3, np.nan), 1.0) is None
    assert M.recovery_threshold(0.1) == 1.0 and M.recovery_threshold(0.5) == 1.5
    assert M.recovery_threshold(None) == M.RECOVERY_FLOOR_M == 1.0


def test_channel_stats_constant_trust_has_zero_variance():
    stats = M.ChannelStats(1, np.array([True, True]))
    a = np.full((1, 2, 3), 0.6)
    for _ in range(50):
        stats.add(a, a, np.ones((1, 2, 3), dtype=bool), np.zeros((1, 2, 3), dtype=bool))
    assert stats.weight_var(0) == pytest.approx(0.0, abs=1e-20)
    assert stats.anomaly_detection_rate(0) is None
