"""``swarmloc compare``: two results files paired episode by episode, checked against closed forms
and against the leaderboard's own ranking rule."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from rich.console import Console

from swarmloc.cli import compare as cli
from swarmloc.bench.scoring.compare import compare
from swarmloc.bench.evaluation.results import EpisodeMetrics, MethodInfo, SuiteInfo, make_results, write_results
from swarmloc.bench.scoring.score import separable_ranks, suite_score

SUITE = SuiteInfo(name="tiny", version="1", sha256="0" * 64)


def _results(name: str, rmse: dict[str, list[float | None]], uniform: float = 1.0, seeds=None, suite=SUITE):
    """A results file whose episodes of each task have these RMSE (uniform's RMSE ``uniform``)."""
    episodes = [{"task": f"swarmloc/{task}", "seed": (seeds or range(len(values)))[i],
                 "metrics": EpisodeMetrics.of(rmse=r, uniform_rmse=uniform).model_dump()}
                for task, values in rmse.items() for i, r in enumerate(values)]
    method = MethodInfo(name=name, entry_point=name, privileged=False, track="A", deterministic=True)
    return make_results(method, suite, episodes)


def test_half_the_error_everywhere_is_one_log2_ahead_beyond_doubt():
    a = _results("a", {"X-v1": [1.0, 2.0, 0.5], "Y-v1": [3.0, 3.0, 1.0]})
    b = _results("b", {"X-v1": [0.5, 1.0, 0.25], "Y-v1": [1.5, 1.5, 0.5]})
    c = compare(a, b)
    assert [t.task for t in c.tasks] == ["swarmloc/X-v1", "swarmloc/Y-v1"]
    for t in c.tasks:
        d = t.difference
        assert d.mean == pytest.approx(1.0) and d.ci_low == pytest.approx(1.0) and d.ci_high == pytest.approx(1.0)
        assert (d.ahead, d.count) == (3, 3)
    assert c.difference.mean == pytest.approx(1.0) and c.difference.ci_low == pytest.approx(1.0)
    assert c.b_ahead and (c.difference.ahead, c.difference.count) == (2, 2)
    assert c.tasks[0].rmse_a == pytest.approx(3.5 / 3) and c.tasks[0].rmse_b == pytest.approx(1.75 / 3)
    # the other way round: A ahead, the CI below 0
    back = compare(b, a)
    assert back.difference.ci_high == pytest.approx(-1.0) and not back.b_ahead


def test_the_difference_is_the_mean_log_ratio_of_the_errors_uniform_cancels():
    rng = np.random.default_rng(3)
    ra, rb = rng.uniform(0.2, 5.0, size=(2, 8))
    c = compare(_results("a", {"X-v1": list(ra)}, uniform=0.7), _results("b", {"X-v1": list(rb)}, uniform=0.7))
    assert c.tasks[0].difference.mean == pytest.approx(float(np.mean(np.log2(ra / rb))))
    assert c.tasks[0].gain_a == pytest.approx(float(np.mean(np.log2(0.7 / ra))))
    assert c.tasks[0].difference.ahead == int(np.sum(rb < ra))


def test_b_is_ahead_exactly_when_the_leaderboard_would_rank_it_ahead():
    rng = np.random.default_rng(0)
    verdicts = set()
    for trial in range(12):
        base = rng.uniform(0.5, 2.0, size=(3, 6))
        lead = rng.normal(0.05 * (trial - 4), 0.2, size=(3, 6))  # B's gain over A per episode
        a = _results("a", {f"T{i}-v1": list(base[i]) for i in range(3)})
        b = _results("b", {f"T{i}-v1": list(base[i] / 2.0 ** lead[i]) for i in range(3)})
        c = compare(a, b)
        ranks = separable_ranks([suite_score(e.model_dump() for e in r.episodes) for r in (b, a)])
        assert c.b_ahead == (ranks == [1, 2])
        assert (c.difference.ci_high < 0) == (ranks == [2, 1])
        assert c.difference.mean == pytest.approx(float(lead.mean(axis=1).mean()))
        verdicts.add(ranks[0] - ranks[1])
    assert verdicts == {-1, 0, 1}  # the trials reach every verdict


def test_only_common_covered_episodes_are_compared_and_the_rest_is_listed():
    a = _results("a", {"X-v1": [1.0, 1.0, 1.0], "Y-v1": [1.0, 1.0, 1.0], "Z-v1": [1.0, 1.0, 1.0]})
    b = _results("b", {"X-v1": [0.5, 0.5], "Y-v1": [0.5, None], "W-v1": [0.5, 0.5]})
    c = compare(a, b)
    assert [t.task for t in c.tasks] == ["swarmloc/X-v1"]
    assert c.tasks[0].difference.count == 2  # seeds 0 and 1: the ones both files hold
    assert dict(c.left_out) == {"swarmloc/Y-v1": "not covered by B (null RMSE)", "swarmloc/Z-v1": "only in A",
                                "swarmloc/W-v1": "only in B"}
    old = _results("b", {"X-v1": [0.5, 0.5]}, uniform=None)  # written before schema 2: no uniform_rmse
    with pytest.raises(ValueError, match="not covered by B \\(no uniform_rmse: a results file older than schema 2"):
        compare(a, old)
    apart = _results("b", {"X-v1": [0.5]}, seeds=[9])
    with pytest.raises(ValueError, match="share no covered task.*no seed in common"):
        compare(a, apart)


def test_episodes_whose_uniform_differs_are_not_the_same_world():
    with pytest.raises(ValueError, match="X-v1 seed 0: uniform's RMSE is 1.0 in A and 1.5 in B"):
        compare(_results("a", {"X-v1": [1.0]}), _results("b", {"X-v1": [0.5]}, uniform=1.5))


def test_results_of_different_suites_do_not_compare_a_part_of_one_does():
    other = SuiteInfo(name="other", version="1", sha256="1" * 64)
    with pytest.raises(ValueError, match="different suites \\('tiny' and 'other'\\)"):
        compare(_results("a", {"X-v1": [1.0]}), _results("b", {"X-v1": [1.0]}, suite=other))
    part = SuiteInfo(name="tiny-subset", version="1", sha256="2" * 64)  # swarmloc evaluate --tasks
    c = compare(_results("a", {"X-v1": [1.0], "Y-v1": [1.0]}), _results("b", {"X-v1": [0.5]}, suite=part))
    assert [t.task for t in c.tasks] == ["swarmloc/X-v1"] and c.difference.mean == pytest.approx(1.0)


def test_the_command_prints_the_verdict_and_writes_the_json(tmp_path):
    pa, pb, out = tmp_path / "a.json", tmp_path / "b.json", tmp_path / "cmp.json"
    write_results(pa, _results("a", {"X-v1": [1.0, 2.0]}))
    write_results(pb, _results("b", {"X-v1": [0.5, 1.0], "Q-v1": [1.0, 1.0]}))
    console = Console(record=True, width=300)
    assert cli.run(cli.Options(a=pa, b=pb, json=out), console) == 0
    text = console.export_text()
    assert "verdict: B is ahead beyond doubt" in text and "left out: swarmloc/Q-v1 (only in B)" in text
    data = json.loads(out.read_text())
    assert data["difference"]["mean"] == pytest.approx(1.0) and data["b_ahead"] is True
    assert data["tasks"][0]["rmse_b"] == pytest.approx(0.75)
    # gains A (0, −1), B (1, 0): of the four pairs B wins three and ties one (rliable counts a tie ½)
    assert math.isclose(data["p_improvement"], 3.5 / 4)


@pytest.mark.parametrize("problem", ["resamples", "missing", "suite"])
def test_the_command_refuses_bad_input_with_status_2(tmp_path, problem):
    pa, pb = tmp_path / "a.json", tmp_path / "b.json"
    write_results(pa, _results("a", {"X-v1": [1.0]}))
    suite = SuiteInfo(name="other", version="1", sha256="1" * 64) if problem == "suite" else SUITE
    if problem != "missing":
        write_results(pb, _results("b", {"X-v1": [1.0]}, suite=suite))
    console = Console(record=True, width=300)
    opts = cli.Options(a=pa, b=pb, resamples=0 if problem == "resamples" else 100)
    assert cli.run(opts, console) == 2
    expected = {"resamples": "--resamples must be >= 1, got 0", "missing": "does not exist",
                "suite": "different suites"}[problem]
    assert expected in console.export_text() and not (tmp_path / "cmp.json").exists()


def test_shipped_names_the_shipped_results_of_the_other_files_suite(tmp_path):
    """``shipped:<method>`` reads the packaged results of a reference method on the other side's suite
    (the default board's, standard-v2, when both are shipped), so the README's comparison works from an installed
    wheel too."""
    from swarmloc.bench.evaluation.results import load_results
    from swarmloc.bench.evaluation.shipped import RESULTS_DIRS

    console = Console(record=True, width=300)
    assert cli.run(cli.Options(a="shipped:uniform", b="shipped:oracle"), console) == 0
    text = console.export_text()
    assert "A: uniform (shipped:uniform)" in text and "B: oracle (shipped:oracle)" in text
    for track in ("cooperative", "robust-ranging"):
        assert f"B against A on standard-v2, {track} track" in text
        assert f"verdict ({track} track): B is ahead beyond doubt" in text
    mine = tmp_path / "mine.json"
    mine.write_text((RESULTS_DIRS["standard-v0"] / "chi2-soft.json").read_text())
    a, b = cli._load_pair("shipped:uniform", str(mine))
    assert a.suite.name == b.suite.name == "standard-v0"
    assert a == load_results(RESULTS_DIRS["standard-v0"] / "uniform.json")
    console = Console(record=True, width=300)
    assert cli.run(cli.Options(a="shipped:nope", b=str(mine)), console) == 2
    assert "no shipped results of 'nope' on standard-v0; shipped: " in console.export_text()
