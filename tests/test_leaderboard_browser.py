"""The generated leaderboard site in headless Chromium: it loads, lists, sorts, and shows its plots.

Needs Debian's Chromium at /usr/bin/chromium (``apt-get install chromium``; ``.ci/run``
installs it) and the Playwright Python client. A screenshot goes to ``test-artifacts/``.
"""

from __future__ import annotations

from pathlib import Path

import lb_helpers as H
import pytest

from swarmloc.leaderboard.store.database import LeaderboardStore
from swarmloc.leaderboard.submit.pipeline import submit
from swarmloc.leaderboard.verify.verification import Tolerance
from swarmloc.leaderboard.site.views import render_html

pytestmark = pytest.mark.browser

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--no-first-run",
]
ARTIFACTS = Path(__file__).resolve().parents[1] / "test-artifacts"


def _build_site(tmp_path: Path) -> Path:
    url = f"sqlite:///{tmp_path / 'lb.db'}"
    methods = [("mid", 0.0, False), ("high", 0.4, False), ("low", -0.3, False),
               ("oracle", 0.6, True)]
    with LeaderboardStore(url) as store:
        # the reference of the score (these results files carry no uniform_rmse: the views take it from here)
        uniform = H.make_results_file(tmp_path / "uniform.json", "uniform")
        submit(uniform, "uniform", {"name": "uniform", "track": "A"}, trust=True, **H.submit_options(url), store=store)
        for name, offset, privileged in methods:
            entry = f"lb_fake_runner:good_{name}"
            path = H.make_results_file(
                tmp_path / f"{name}.json", entry, privileged=privileged,
                metrics_edit=lambda t, s, m, o=offset: m.update(rmse=m["rmse"] - o / 10),
            )
            # The fake runner reproduces the unshifted metrics; accept the shift here.
            submit(path, entry, {"name": name, "track": "A", "privileged": privileged},
                   **(H.submit_options(url) | {"tolerance": Tolerance(abs=1.0)}), store=store)
        # per-method plots would re-run episodes (the fake methods cannot); the suite plots are drawn
        return render_html(store, tmp_path / "site", plots=False)


def test_page_loads_shows_one_row_per_method_and_sorts(tmp_path: Path) -> None:
    if not CHROMIUM.exists():
        pytest.skip("Chromium not found at /usr/bin/chromium; enable this test with "
                    "`apt-get install chromium` (Debian), as .ci/run does")
    sync_api = pytest.importorskip("playwright.sync_api")
    index = _build_site(tmp_path)
    ranked = "#ranked-tiny-test-1"

    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 700})
            problems: list[str] = []
            requests: list[str] = []
            page.on("pageerror", lambda err: problems.append(str(err)))
            page.on("console", lambda msg: problems.append(msg.text) if msg.type == "error" else None)
            page.on("request", lambda req: requests.append(req.url))
            page.goto(index.as_uri())
            page.wait_for_selector("html[data-sortable-ready=true]", timeout=10_000)

            def names() -> list[str]:
                return page.locator(f"{ranked} tbody tr td:nth-child(2)").all_inner_texts()

            assert page.title() == "swarmloc leaderboard"
            assert page.locator(f"{ranked} tbody tr").count() == 4  # one row per method
            # ranked by the score: "mid" ties uniform (the same RMSE), which is older
            assert names() == ["high", "uniform", "mid", "low"]
            privileged = page.locator("#privileged-tiny-test-1 tbody tr td:first-child")
            assert privileged.all_inner_texts() == ["oracle"]

            method_header = page.locator(f"{ranked} thead th", has_text="Method")
            method_header.locator("button").click()
            assert names() == ["high", "low", "mid", "uniform"]
            assert method_header.get_attribute("aria-sort") == "ascending"
            method_header.locator("button").click()
            assert names() == ["uniform", "mid", "low", "high"]
            assert method_header.get_attribute("aria-sort") == "descending"
            score_header = page.locator(f"{ranked} thead th", has_text="2^S")
            score_header.locator("button").click()
            assert names()[0] == "low" and names()[-1] == "high"  # ascending 2^S
            assert method_header.get_attribute("aria-sort") is None
            score_header.locator("button").click()
            assert names()[0] == "high" and names()[-1] == "low"

            # the suite plots, drawn by matplotlib at build time, are on the page and decoded
            plots = page.locator(".suite-plots img")
            assert plots.count() == 3  # score with CI, gain heatmap, performance profiles
            for i in range(plots.count()):
                img = plots.nth(i)
                img.scroll_into_view_if_needed()
                page.wait_for_function("img => img.complete", arg=img.element_handle(), timeout=10_000)
                assert img.evaluate("img => img.naturalWidth") > 0, img.get_attribute("src")
            assert page.locator(".suite-plots figcaption").first.inner_text().startswith("2^S per method")

            ARTIFACTS.mkdir(exist_ok=True)
            page.evaluate("window.scrollTo(0, 0)")  # sticky table headers follow the scroll
            page.screenshot(path=str(ARTIFACTS / "leaderboard.png"), full_page=True)

            page.locator(f"{ranked} a", has_text="high").click()
            page.wait_for_selector("h1")
            assert page.locator("h1").inner_text() == "high"
            assert page.locator("a[download]").get_attribute("href").endswith(".json")
            page.screenshot(path=str(ARTIFACTS / "leaderboard-method.png"), full_page=True)

            assert problems == []
            assert requests and all(u.startswith("file://") for u in requests), requests
        finally:
            browser.close()
