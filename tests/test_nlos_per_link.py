"""One Gauss–Markov NLOS state per peer link (``NlosGaussMarkov.peer_state="per_link"``).

Under ``per_link`` the channel of UAV i ranging j and that of j ranging i share the NLOS-prone
draw, the onsets and the bias at every step (their draws are keyed by the unordered pair,
``faults.gm_draw_keys``); under the default ``per_channel`` they are independent, and every
v0/v1 task keeps its draws (the keys are ``i·L + l``, the index the kernel always used).
"""

from __future__ import annotations

import numpy as np

from swarmloc.envs.tasks.catalogue import CATALOGUE, get_spec
from swarmloc.envs.tasks.channels import PEER
from swarmloc.envs.world.faults import gm_draw_keys
from swarmloc.envs.world.sim import World

#: Scale6-v1 with frequent, long NLOS episodes on half of the peer links (so the prone draw matters)
OVERRIDES = {"duration": 8.0, "faults": {"nlos_gauss_markov": {"onset_rate": 0.5, "link_fraction": 0.5}}}


def _spec(peer_state: str):
    overrides = {**OVERRIDES, "faults": {"nlos_gauss_markov": {**OVERRIDES["faults"]["nlos_gauss_markov"],
                                                               "peer_state": peer_state}}}
    return get_spec("swarmloc/Scale6-v1", **overrides)


def _peer_pairs(world: World) -> list[tuple[int, int, int, int]]:
    """(i, l, j, m): UAV i's channel l ranges UAV j, whose channel m ranges i (i < j)."""
    kind, target = world.layout.kind, world.layout.target
    pairs = []
    for i, l in zip(*np.nonzero(kind == PEER)):
        j = int(target[i, l])
        if i < j:
            m = int(np.nonzero((kind[j] == PEER) & (target[j] == i))[0][0])
            pairs.append((int(i), int(l), j, m))
    return pairs


def _biases(peer_state: str, seeds: list[int]) -> tuple[World, np.ndarray, np.ndarray]:
    """The world and its (T, B, N, L) range bias (``systematic[..., 0]``) and ``injected`` per step."""
    spec = _spec(peer_state)
    world = World(spec, len(seeds))
    world.reset(seeds)
    systematic, injected = [], []
    for _ in range(spec.n_steps):
        buf = world.sense()
        systematic.append(buf.systematic[..., 0].copy())
        injected.append(buf.injected.copy())
    return world, np.array(systematic), np.array(injected)


def test_per_link_directions_share_one_state_per_channel_ones_do_not():
    seeds = [4, 91, 2**33]
    world, bias, injected = _biases("per_link", seeds)
    pairs = _peer_pairs(world)
    mask = world.schedule.gm_mask
    assert len(pairs) == 15
    for i, l, j, m in pairs:
        # one prone draw per link; the same bias in both directions at every step
        assert np.array_equal(mask[:, i, l], mask[:, j, m])
        assert np.array_equal(bias[:, :, i, l], bias[:, :, j, m])
        assert np.array_equal(injected[:, :, i, l], injected[:, :, j, m])
    # not trivially: some links are prone and some are not, and their episodes carry biases
    prone = np.array([mask[:, i, l] for i, l, _, _ in pairs])
    assert 0.2 < prone.mean() < 0.8
    assert (bias > 0.1).mean() > 0.05

    world, bias, _ = _biases("per_channel", seeds)
    mask = world.schedule.gm_mask
    assert any(not np.array_equal(mask[:, i, l], mask[:, j, m]) for i, l, j, m in pairs)
    both = [(b, i, l, j, m) for b in range(len(seeds)) for i, l, j, m in pairs if mask[b, i, l] and mask[b, j, m]]
    assert len(both) > 5
    assert all(not np.array_equal(bias[:, b, i, l], bias[:, b, j, m]) for b, i, l, j, m in both)


def test_per_link_batched_equals_single_runs_exactly():
    seeds = [7, 0, 123456]
    _, bias, injected = _biases("per_link", seeds)
    for b, seed in enumerate(seeds):
        _, bias_1, injected_1 = _biases("per_link", [seed])
        assert np.array_equal(bias[:, b], bias_1[:, 0]) and np.array_equal(injected[:, b], injected_1[:, 0])


def test_per_channel_keys_are_the_channel_index_and_the_default_stays_out_of_the_spec():
    # the kernel keyed every Gauss–Markov draw by i·L + l before per_link existed: that key stays
    world = World(get_spec("swarmloc/Scale6-v1"), 1)
    n, n_l = world.layout.kind.shape
    assert np.array_equal(world.schedule.gm_key, np.arange(n * n_l).reshape(n, n_l))
    linked = gm_draw_keys(world.layout, per_link=True)
    for i, l, j, m in _peer_pairs(world):
        assert linked[i, l] == linked[j, m] == i * n_l + l
    anchors = world.layout.kind != PEER
    assert np.array_equal(linked[anchors], world.schedule.gm_key[anchors])
    # the default is left out of the canonical JSON, so no v0/v1 task's spec (or hash) changes
    for task_id in CATALOGUE:
        spec = get_spec(task_id)
        g = spec.faults.nlos_gauss_markov
        if spec.version < 2:
            assert g is None or (g.peer_state == "per_channel" and "peer_state" not in g.model_dump())
    assert _spec("per_link").faults.nlos_gauss_markov.model_dump()["peer_state"] == "per_link"
