"""The documentation site builds with ``mkdocs build --strict`` and its API page shows the docstrings.

Strict: a link to a page or heading that does not exist, or a docstring that mkdocstrings
cannot resolve, fails the build (mkdocs.yml). The build takes a few seconds; it needs the
``docs`` extra (part of ``dev``).
"""

from __future__ import annotations

import html
import inspect
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    pytest.importorskip("mkdocs", reason="the docs extra is not installed")
    pytest.importorskip("mkdocstrings", reason="the docs extra is not installed")
    out = tmp_path_factory.mktemp("site")
    build = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                           check=False, cwd=ROOT, capture_output=True, text=True, timeout=300,
                           env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert build.returncode == 0, f"mkdocs build --strict failed:\n{build.stdout}\n{build.stderr}"
    return out


def test_the_api_page_shows_the_stable_api(site: Path) -> None:
    from swarmloc.bench import evaluate_task
    from swarmloc.envs import make_vec

    page = (site / "api" / "index.html").read_text(encoding="utf-8")
    for name in ("evaluate", "evaluate_task", "get_suite", "load_results", "compare"):
        assert f'id="swarmloc.bench.{name}"' in page, f"the API page lacks swarmloc.bench.{name}"
    for name in ("make", "make_vec", "parallel_env", "get_spec"):
        assert f'id="swarmloc.envs.{name}"' in page, f"the API page lacks swarmloc.envs.{name}"
    # the page's text without markup or spacing (a code span's tags sit inside a sentence)
    text = "".join(html.unescape(re.sub(r"<[^>]+>", "", page)).split())
    for function in (evaluate_task, make_vec):
        summary = inspect.getdoc(function).split("\n\n")[0]  # the first paragraph, as rendered
        summary = "".join(summary.replace("``", "").split())
        assert summary in text, f"the API page lacks the docstring of {function.__name__}: {summary!r}"


def test_every_page_is_in_the_site(site: Path) -> None:
    for page in sorted(DOCS.glob("*.md")):
        built = site / ("index.html" if page.stem == "index" else f"{page.stem}/index.html")
        assert built.is_file(), f"docs/{page.name} was not built"


def test_every_hand_written_page_is_in_the_nav() -> None:
    import yaml

    def pages(nav) -> list[str]:
        if isinstance(nav, str):
            return [nav]
        if isinstance(nav, dict):
            return [p for value in nav.values() for p in pages(value)]
        return [p for item in nav for p in pages(item)]

    config = yaml.load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"), Loader=yaml.SafeLoader)
    listed = set(pages(config["nav"]))
    missing = [page.name for page in sorted(DOCS.glob("*.md")) if page.name not in listed]
    assert not missing, f"pages missing from mkdocs.yml's nav: {missing}"
