"""``isam2-robust``: the fixed-lag factor-graph smoother against a closed form, batched == single, the robust
kernel against a gross outlier, every channel kind, and the registry and extra it ships with."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")

from swarmloc.agents.estimators.isam2 import ISAM2Config, ISAM2Robust  # noqa: E402
from swarmloc.agents.protocols import Measurements, TaskFacts, episode_keys  # noqa: E402
from swarmloc.agents.registry import get_entry, load_method  # noqa: E402
from swarmloc.cli.extras import missing_extra  # noqa: E402
from swarmloc.envs.tasks.catalogue import get_spec  # noqa: E402
from swarmloc.envs.tasks.channels import ANCHOR  # noqa: E402
from swarmloc.envs.tasks.seeds import DEV_SEED_START  # noqa: E402
from swarmloc.envs.world.sim import World  # noqa: E402

DEV = [DEV_SEED_START + i for i in range(3)]
ANCHORS = np.array([[0.0, 0.0, 0.5], [10.0, 0.0, 3.0], [10.0, 10.0, 0.5], [0.0, 10.0, 3.0], [5.0, -4.0, 6.0]])
SIGMA = np.array([0.10, 0.15, 0.20, 0.15, 0.10])
TRUTH = np.array([3.0, 4.0, 1.5])
DT = 0.1


def _static_facts(n_steps: int) -> TaskFacts:
    """One UAV among the five anchors, its prior 0.5 m off the truth."""
    n_l = len(ANCHORS)
    x0 = np.concatenate([TRUTH + [0.3, -0.4, 0.0], np.zeros(3)])[None, None]
    return TaskFacts(task_id="test/static", dt=DT, n_steps=n_steps, duration=n_steps * DT, n_uav=1,
                     kind=np.full((1, n_l), ANCHOR), target=np.arange(n_l)[None], linked=np.ones((1, n_l), bool),
                     sigma=SIGMA[None], anchors=ANCHORS, landmarks=np.zeros((0, 3)), imu_sigma=0.1, x0=x0,
                     init_pos_sigma=1.0, init_vel_sigma=0.5, alpha_th=0.05, alpha_min=0.01, keys=np.zeros(1, np.int64))


def _run_static(est, z: np.ndarray, n_steps: int = 60) -> np.ndarray:
    """Feed the same ranges ``z`` ``(A,)`` and a zero IMU for ``n_steps``; the last position estimate ``(3,)``."""
    facts = _static_facts(n_steps)
    est.reset(facts, facts.x0)
    zz = np.zeros((1, 1, len(z), 3))
    zz[..., 0] = z
    valid = np.ones((1, 1, len(z)), bool)
    for k in range(1, n_steps + 1):
        out = est.step(Measurements.capture(np.zeros((1, 1, 3)), zz, valid, k * DT, k))
    return out.positions[0, 0]


def _least_squares_fix(z: np.ndarray, w: np.ndarray, p: np.ndarray) -> np.ndarray:
    """argmin_p Σ w_a (z_a − ‖p − a‖)², Gauss–Newton from ``p`` to convergence."""
    for _ in range(50):
        d = p - ANCHORS
        r = np.linalg.norm(d, axis=1)
        H = d / r[:, None]
        # Δp = (Hᵀ W H)⁻¹ Hᵀ W (z − h(p))
        p = p + np.linalg.solve(H.T @ (w[:, None] * H), H.T @ (w * (z - r)))
    return p


def test_static_uav_among_five_anchors_converges_to_the_weighted_least_squares_fix():
    # each anchor's range off by a constant error below the Huber threshold: the kernel is quadratic there
    err = np.array([0.08, -0.12, 0.15, 0.05, -0.09])
    z = np.linalg.norm(TRUTH - ANCHORS, axis=1) + err
    fix = _least_squares_fix(z, SIGMA**-2, TRUTH.copy())
    assert np.linalg.norm(fix - TRUTH) > 0.05  # the fix is not the truth: the test sees the weighting
    est = _run_static(ISAM2Robust(), z)
    np.testing.assert_allclose(est, fix, atol=2e-3)


def test_robust_kernels_keep_a_5_m_outlier_from_dragging_the_estimate():
    # anchor 1's range 5 m (33 σ) long at every step, the other four exact
    z = np.linalg.norm(TRUTH - ANCHORS, axis=1)
    z[1] += 5.0
    error = {kernel: np.linalg.norm(_run_static(ISAM2Robust(ISAM2Config(kernel=kernel)), z) - TRUTH)
             for kernel in ("huber", "cauchy", "gaussian")}
    assert error["gaussian"] > 1.0  # least squares: dragged metres away
    assert error["huber"] < 0.25  # bounded influence: the outlier pulls with k σ at most (measured 0.19 m)
    assert error["cauchy"] < 0.05  # redescending: the outlier all but ignored (measured 0.02 m)


def _record(spec, seeds):
    world = World(spec, len(seeds))
    x0 = world.reset(seeds).copy()
    facts = TaskFacts.from_spec(spec, world.layout, x0, episode_keys(seeds), anchors=world.anchors)
    meas, truth = [], []
    for k in range(1, spec.n_steps + 1):
        buf = world.sense()
        vel = getattr(buf, "velocity", None) if facts.velocity_sigma is not None else None
        meas.append(Measurements.capture(buf.imu, buf.z, buf.valid, k * spec.dt, k, velocity=vel))
        truth.append(np.array(buf.pos))
    return facts, meas, np.array(truth)


def _play(est, facts, meas):
    est.reset(facts, facts.x0)
    outs = [est.step(m) for m in meas]
    return np.array([o.positions for o in outs]), np.array([o.cov for o in outs])


def test_batched_equals_single():
    spec = get_spec("swarmloc/Scale8-v2", n_uav=3, duration=1.5)
    facts, meas, _ = _record(spec, DEV)
    pos, cov = _play(ISAM2Robust(), facts, meas)
    for b in range(len(DEV)):
        one = dataclasses.replace(facts, x0=facts.x0[b:b + 1], keys=facts.keys[b:b + 1])
        sliced = [Measurements.capture(m.imu[b:b + 1], m.z[b:b + 1], m.valid[b:b + 1], m.t, m.step) for m in meas]
        p1, c1 = _play(ISAM2Robust(), one, sliced)
        np.testing.assert_array_equal(p1[:, 0], pos[:, b])
        np.testing.assert_array_equal(c1[:, 0], cov[:, b])


# one task per channel kind: anchor + peer range, TDOA, landmark, GPS + relative position
KINDS = [("swarmloc/Scale8-v2", {"n_uav": 3}), ("swarmloc/TDOA-v1", {"n_uav": 1}),
         ("swarmloc/Indoor-v1", {"n_uav": 2}), ("swarmloc/GradualFault-v2", {})]


@pytest.mark.parametrize("task, changes", KINDS, ids=[t for t, _ in KINDS])
def test_every_channel_kind_runs_and_tracks(task, changes):
    spec = get_spec(task, **changes)
    spec = get_spec(task, duration=20 * spec.dt, **changes)
    facts, meas, truth = _record(spec, DEV[:1])
    assert any(m.valid.any() for m in meas)
    pos, cov = _play(ISAM2Robust(), facts, meas)
    assert np.isfinite(pos).all() and np.isfinite(cov).all()
    assert (np.linalg.eigvalsh(cov) > 0).all()
    # tracking: the last step's mean error below the initial prior's std
    assert np.linalg.norm(pos[-1] - truth[-1], axis=-1).mean() < facts.init_pos_sigma


def test_registry_entry_and_extra():
    entry = get_entry("isam2-robust")
    assert (entry.track, entry.privileged, entry.deterministic) == ("B", False, True)
    loaded = load_method("isam2-robust")
    assert isinstance(loaded.method, ISAM2Robust) and loaded.track == "B"
    assert missing_extra(ModuleNotFoundError("No module named 'gtsam'", name="gtsam"), "evaluate") == "factorgraph"


def test_wrong_prior_shape_is_refused():
    facts = _static_facts(3)
    with pytest.raises(ValueError, match="x0 must have shape"):
        ISAM2Robust().reset(facts, np.zeros((1, 2, 6)))


def test_the_registered_smoother_refuses_swarms_above_its_limit():
    from swarmloc.agents.estimators.isam2 import MAX_UAVS
    from swarmloc.agents.protocols import UnsupportedTask

    method = load_method("isam2-robust").method
    big, _, _ = _record(get_spec("swarmloc/Scale8-v2", duration=2 * DT), DEV[:1])
    with pytest.raises(UnsupportedTask, match=f"8 UAVs: isam2-robust runs swarms of at most {MAX_UAVS}"):
        method.reset(big, big.x0)
    small, _, _ = _record(get_spec("swarmloc/Scale8-v2", n_uav=MAX_UAVS, duration=2 * DT), DEV[:1])
    method.reset(small, small.x0)  # at the limit: runs
    ISAM2Robust().reset(big, big.x0)  # the estimator itself has no limit
