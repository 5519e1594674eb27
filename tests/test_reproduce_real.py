"""``swarmloc reproduce real``: the sim-to-real report, on shortened episodes (the full run is the command's)."""

from __future__ import annotations

import json

import pytest

from swarmloc.bench.evaluation.suites import get_suite, missing_data
from swarmloc.bench.reproduce.real import PLOT_PAIRS, reproduce_real

MISSING = missing_data(get_suite("real-v1"))


def test_without_data_it_says_where_the_data_comes_from(tmp_path, monkeypatch):
    monkeypatch.setenv("SWARMLOC_DATA", str(tmp_path))
    with pytest.raises(FileNotFoundError, match="utiasDSL/util-uwb-dataset"):
        reproduce_real(tmp_path / "real.md", ["uniform"], workers=1, seeds=1, progress=False)
    with pytest.raises(ValueError, match="seeds must be in 1"):
        reproduce_real(tmp_path / "real.md", ["uniform"], seeds=5)


@pytest.mark.skipif(bool(MISSING), reason=f"UTIL data absent: {next(iter(MISSING.values()), '').splitlines()[:1]}")
def test_report_on_shortened_flights(tmp_path):
    path = reproduce_real(tmp_path / "real.md", ["uniform", "chi2-gate", "oracle", "pf"], workers=1, seeds=1,
                          tasks=PLOT_PAIRS[0], overrides={"duration": 1.0}, progress=False)
    text = path.read_text()
    for part in ("## Per flight", "C0426Tdoa2NoLabel", "C0426Tdoa2WoodCardPlasticMetal", "LOS: uniform",
                 "metal: oracle", "filtering rules", "## Every registered method",
                 "Not the suite's numbers", "do not model TDOA"):
        assert part in text, part
    raw = json.loads(path.with_suffix(".json").read_text())
    assert set(raw["rmse"]) == {"uniform", "chi2-gate", "oracle", "pf"}
    assert raw["rmse"]["pf"]["swarmloc/UTILC0426Tdoa2NoLabel-v1"] is None
    assert raw["diagnostics"]["swarmloc/UTILC0426Tdoa2WoodCardPlasticMetal-v1"]["impossible"] >= 0
    assert (tmp_path / "real_error_vs_time.png").stat().st_size > 10_000
