"""Explanations of trust decisions (issue 19): completeness, sanity, dummy features, the CLI.

Episodes are short: a 5 s NLOSStep with its +3 m anchor-0 step moved to 2–4 s, so the
onset, the fault and the recovery all happen; few channels where the cost grows with L.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

pytest.importorskip("captum")

from swarmloc.agents.mappo.policy import ChannelActor, MappoPolicy, weights_kinds
from swarmloc.agents.registry import WEIGHTS_DIR, LoadedMethod, load_method
from swarmloc.bench.explain import attribute, explain, replay
from swarmloc.bench.explain.features import FEATURE_GROUP, GROUP_NAMES
from swarmloc.bench.explain.report import summarize
from swarmloc.envs.world.observation import NIS, SCALE_NIS, unsquash
from swarmloc.envs.tasks.specs import Faults, NlosStep, Scoring
from swarmloc.envs.tasks.catalogue import get_spec

SEED = 1_000_000


@pytest.fixture(scope="module")
def spec():
    step = NlosStep(target="anchor", index=0, start=2.0, end=4.0, bias=3.0)
    return get_spec("swarmloc/NLOSStep-v0", duration=5.0, faults=Faults(nlos_steps=(step,)),
                    scoring=Scoring(fault_window=(2.0, 4.0)))


@pytest.fixture(scope="module")
def mappo_episode(spec):
    return replay("mappo-no-smoothing", spec, [SEED])


def _loaded(name: str, method) -> LoadedMethod:
    return LoadedMethod(name, f"test:{name}", "A", False, True, method)


class NisOnlyTrust:
    """α = 1 / (1 + NIS): reads the raw NIS field and nothing else."""

    privileged = False
    flops_per_channel = 2.0

    def reset(self, batch_size, layout, keys):
        pass

    def act(self, inp):
        return 1.0 / (1.0 + np.asarray(inp.nis))


class TorchNisOnlyTrust(NisOnlyTrust):
    """The same rule as a torch policy: α = 1 / (1 + unsquash(NIS feature)), explained by integrated gradients."""

    def torch_trust(self, obs: torch.Tensor) -> torch.Tensor:
        y = obs[..., NIS]
        return 1.0 / (1.0 + SCALE_NIS * y / (1.0 - y))


def _rows_gap(a) -> np.ndarray:
    explained = ~np.isnan(a.values[..., 0])
    total = a.values.sum(axis=-1)
    return np.abs(total - (a.trust - a.baseline_trust))[explained]


@pytest.mark.parametrize("method,baseline", [("mappo", "nominal"), ("mappo-no-smoothing", "zeros")])
def test_integrated_gradients_are_complete(spec, method, baseline):
    """Σ_f attributions = α(x) − α(x̄) within 1e-4 on every step and channel, and α(x) is the method's own."""
    ep = replay(method, spec, [SEED])
    a = attribute(method, ep, explainer="integrated-gradients", baseline=baseline, channels=[0, 1, 4])
    assert a.explainer == "integrated-gradients"
    assert a.values.shape == (*ep.trust.shape, 11)
    gap = _rows_gap(a)
    assert gap.size == ep.n_steps * 4 * 3
    assert gap.max() <= 1e-4, gap.max()
    assert a.completeness_gap <= 1e-4
    np.testing.assert_allclose(a.trust, ep.trust, atol=1e-6)  # the method flew the episode it explains
    assert np.isnan(a.values[:, :, :, 2]).all()  # channels not asked for stay empty
    # the drop on the attacked anchor is explained, not absorbed: its attributions are large in the window
    inside = (ep.times >= 2.0) & (ep.times < 4.0)
    assert np.abs(a.values[inside, 0, :, 0]).sum(axis=-1).mean() > 0.3


def test_sanity_randomised_actor_explains_differently(mappo_episode):
    """Adebayo et al. 2018: the trained actor's attributions are not those of a randomly initialised actor."""
    path = WEIGHTS_DIR / "mappo.pt"
    trained = load_method("mappo-no-smoothing", version=0)  # the v0 weights, those of mappo_episode
    torch.manual_seed(0)
    actor = ChannelActor(context=True)
    for layer in actor.body:
        if isinstance(layer, torch.nn.Linear):
            layer.reset_parameters()  # the fresh actor's head is near zero on purpose; randomise it fully
    random = _loaded("random-actor", MappoPolicy(actor.eval(), kinds=weights_kinds(path)))
    channels = [0, 1, 4]
    a = attribute(trained, mappo_episode, explainer="integrated-gradients", channels=channels)
    r = attribute(random, mappo_episode, explainer="integrated-gradients", channels=channels)
    assert r.completeness_gap <= 1e-4
    # the features that move away from the nominal baseline (distance, kind and valid stay: zero for both)
    moving = [0, 2, 3, 4]
    explained = ~np.isnan(a.values[..., moving])
    va, vr = a.values[..., moving][explained], r.values[..., moving][explained]
    rank = lambda v: np.argsort(np.argsort(np.abs(v)))
    spearman = np.corrcoef(rank(va), rank(vr))[0, 1]
    assert spearman < 0.5, spearman
    assert np.linalg.norm(va - vr) > 0.5 * np.linalg.norm(va)
    # at the onset the trained actor drops the attacked anchor for its innovation and NIS; the random one barely moves
    onset = int(np.argmax(mappo_episode.times >= 2.0 - 1e-9))
    ga, gr = a.grouped()[onset, 0, :, 0], r.grouped()[onset, 0, :, 0]  # (N, G)
    assert {GROUP_NAMES[g] for g in np.argmax(np.abs(ga), axis=-1)} <= {"innovation", "NIS"}
    assert np.all(ga[:, GROUP_NAMES.index("innovation")] < -0.1) and np.all(ga[:, GROUP_NAMES.index("NIS")] < -0.1)
    assert np.abs(gr).sum(axis=-1).max() < 0.2 * np.abs(ga).sum(axis=-1).min()


@pytest.mark.parametrize("explainer,policy", [("shapley-sampling", NisOnlyTrust),
                                              ("integrated-gradients", TorchNisOnlyTrust)])
def test_nis_only_policy_gives_every_other_feature_zero(spec, explainer, policy):
    """A policy whose α depends on NIS only: every other feature gets exactly zero, NIS gets all of the change."""
    method = _loaded("nis-only", policy())
    ep = replay(method, spec, [SEED])
    for baseline in ("nominal", "zeros"):
        a = attribute(_loaded("nis-only", policy()), ep, explainer=explainer, baseline=baseline, channels=[0, 3],
                      n_samples=4)
        explained = ~np.isnan(a.values[..., 0])
        others = np.delete(a.values, NIS, axis=-1)[explained]
        assert np.all(others == 0.0), np.abs(others).max()
        assert _rows_gap(a).max() <= 1e-4
        assert np.abs(a.values[..., NIS][explained]).max() > 0.5  # the attacked anchor's NIS moved α a lot
    np.testing.assert_allclose(a.trust, 1.0 / (1.0 + ep.nis), atol=1e-5)


def test_classical_and_stateful_methods_are_explained_through_act(spec):
    """chi2-gate: only NIS matters; a smoothed rule: the shadow batch keeps the method's own state."""
    ep = replay("chi2-gate", spec, [SEED])
    a = attribute("chi2-gate", ep, channels=[0, 1], n_samples=4)
    assert a.explainer == "shapley-sampling"
    grouped = np.nan_to_num(a.grouped())
    assert np.all(np.delete(grouped, GROUP_NAMES.index("NIS"), axis=-1) == 0.0)
    gated = ep.trust[:, 0, :, 0] < 0.5
    assert gated.any() and np.all(grouped[:, 0, :, 0, GROUP_NAMES.index("NIS")][gated] < -0.9)

    ep = replay("huber+smooth", spec, [SEED, SEED + 1])
    a = attribute("huber+smooth", ep, channels=[0], n_samples=4)
    np.testing.assert_array_equal(a.trust, ep.trust)  # the shadow copies saw exactly what the method saw
    assert a.faithfulness_gap == 0.0 and a.completeness_gap <= 1e-4
    # the smoother's memory is state, not the previous-trust feature: neither huber nor the smoother reads it
    assert np.all(a.grouped()[..., 0, GROUP_NAMES.index("previous trust")] == 0.0)


def test_both_explainers_play_the_same_game(spec):
    """mappo by integrated gradients and by Shapley sampling: same α(x), same α(x̄), similar attributions."""
    ep = replay("mappo", spec, [SEED])
    ig = attribute("mappo", ep, explainer="integrated-gradients", channels=[0])
    sv = attribute("mappo", ep, explainer="shapley-sampling", channels=[0], n_samples=6)
    np.testing.assert_allclose(ig.trust, sv.trust, atol=1e-6)
    np.testing.assert_allclose(ig.baseline_trust, sv.baseline_trust, atol=1e-5, equal_nan=True)
    assert sv.completeness_gap <= 1e-4 and ig.completeness_gap <= 1e-4
    a, b = ig.grouped()[:, 0, :, 0].ravel(), sv.grouped()[:, 0, :, 0].ravel()  # the attacked anchor
    assert np.corrcoef(a, b)[0, 1] > 0.9


def test_explain_summary_and_grouping(spec):
    """The API's arrays line up with the groups; the Table 5 summary counts attacked and normal channels."""
    ex = explain("chi2-gate", spec, [SEED], channels=[0, 1, 2], n_samples=3)
    a = ex.attributions
    assert FEATURE_GROUP.shape == (11,) and a.grouped().shape == (*ex.episode.trust.shape, len(GROUP_NAMES))
    assert a.at(10).shape == ex.episode.trust.shape[1:] + (11,)
    s = summarize(ex)
    assert s["fault_window_s"] == (2.0, 4.0)
    assert s["attacked_channel_steps"] == 4 * 20 and s["normal_channel_steps"] == 4 * 20 * 7
    assert s["alpha_attacked"] < 0.5 < s["alpha_normal"]
    assert s["reference"] == "uniform" and s["fault_rmse"] < s["reference_fault_rmse"]
    assert s["top_features"]["attacked_inside"][0]["feature"] == "NIS"
    json.dumps(s)


def test_refuses_what_it_cannot_explain(spec, mappo_episode):
    with pytest.raises(ValueError, match="Track B"):
        attribute("dead-reckoning", mappo_episode)
    with pytest.raises(ValueError, match="privileged"):
        attribute("oracle", mappo_episode)
    with pytest.raises(ValueError, match="no differentiable form"):
        attribute("chi2-gate", mappo_episode, explainer="integrated-gradients")
    with pytest.raises(ValueError, match="channel 99"):
        attribute("chi2-gate", mappo_episode, channels=[99])
    with pytest.raises(ValueError, match="baseline"):
        attribute("chi2-gate", mappo_episode, baseline="mean")


def test_cli_writes_figure_summary_and_arrays(tmp_path, capsys):
    from swarmloc.cli import main

    out = tmp_path / "ex"
    rc = main(["explain", "--method", "chi2-gate", "--duration", "21", "--channels", "0", "1", "--samples", "3",
               "--out", str(out)])
    assert rc == 0
    assert {p.name for p in out.iterdir()} >= {"figure.png", "summary.md", "summary.json", "attributions.npz"}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["explainer"] == "shapley-sampling" and summary["channels_explained"] == [0, 1]
    assert "Table 5" in capsys.readouterr().out
    with np.load(out / "attributions.npz") as z:
        assert z["values"].shape == (210, 1, 4, 11, 11)
        assert list(z["group_names"]) == list(GROUP_NAMES)
    assert unsquash(np.float64(0.5), 1.0) == 1.0


def test_leaderboard_method_pages_link_their_explanation(tmp_path, monkeypatch):
    """The site explains shipped Track A methods on the step-NLOS task and links it; Track B pages have none."""
    import shutil

    from swarmloc.leaderboard.site import explain as site_explain
    from swarmloc.bench.evaluation.shipped import RESULTS_DIRS
    from swarmloc.leaderboard.store.shipped import load_shipped
    from swarmloc.leaderboard.store.database import LeaderboardStore
    from swarmloc.leaderboard.site.views import render_html

    shipped = tmp_path / "shipped"
    shipped.mkdir()
    for name in ("chi2-gate", "dead-reckoning"):
        shutil.copy(RESULTS_DIRS["standard-v0"] / f"{name}.json", shipped / f"{name}.json")
    monkeypatch.setattr(site_explain, "EXPLAIN_DURATION", 26.0)  # NLOSStep-v1: the biases ramp in over 20–25 s
    with LeaderboardStore(f"sqlite:///{tmp_path / 'lb.db'}") as store:
        assert load_shipped(store, shipped).stored == ("chi2-gate", "dead-reckoning")
        entries = {e.name: e for e in store.entries()}
        site = tmp_path / "site"
        render_html(store, site, plots=False, explanations=True)
    gate = (site / "methods" / f"{entries['chi2-gate'].id}.html").read_text()
    assert "Explanation on swarmloc/NLOSStep-v" in gate and "NIS" in gate
    folder = site / "explain" / str(entries["chi2-gate"].id)
    assert f'src="../explain/{entries["chi2-gate"].id}/figure.png"' in gate
    assert {"figure.png", "summary.md", "summary.json"} <= {p.name for p in folder.iterdir()}
    assert "explanation" not in (site / "methods" / f"{entries['dead-reckoning'].id}.html").read_text()
