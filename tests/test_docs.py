"""The project stands alone: its user-facing text points nowhere outside the repository,
its citations resolve in docs/references.md, and the hand-written docs stay true to the code.

Cheap checks (file reads and the task catalogue, no kernels): run them with
``python -m pytest -q tests/test_docs.py``.
"""

from __future__ import annotations

import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
REFERENCES = DOCS / "references.md"
#: the user-facing text of the repository: what a user who clones it reads
USER_FACING = ("README.md", "CITATION.cff", "docs", "envs", "agents", "bench", "leaderboard")
TEXT_SUFFIXES = {".py", ".md", ".cff", ".json", ".js", ".css", ".txt", ".toml", ".cfg", ".html"}
#: pointers to files that exist only beside the project's own checkout (a clone has none of
#: them); the data loader's default data folder (``../shared/data``) is documented as such
#: and allowed
OUTSIDE = re.compile(r"shared folder|shared/papers|\.\./shared/DESIGN|\bDESIGN(?:\.md)?\b|\bSTYLE\.md\b")
#: a reference key as docs/references.md defines it: ``- **[key]** ...``
DEFINED_KEY = re.compile(r"^\s*-\s+\*\*\[([a-z][a-z0-9]*(?:-[a-z0-9]+)*)\]\*\*", re.M)
#: an explicit citation ``[key]``: not an index (``x[i]``), not a pip extra (``.[dev]``), not a
#: Markdown link (``[t](u)``)
CITED_KEY = re.compile(r"(?<![\w\]\[`'\"(.])\[([a-z][a-z0-9]*(?:-[a-z0-9]+)*)\](?![(\[:])")
#: bracketed words that are not citations: units (``[m]``, ``[s]``, ``[ms]``) and placeholders
NOT_A_CITATION = {"m", "s", "ms", "rad", "j", "w", "hz", "mm", "cm", "km", "kg", "deg", "options", "dirs"}
#: a citation by place: ``madrl §2.3``, ``pf-nn Table 4``, ``dtvirm eq. 38``, ``federated Scheme 2``
CITED_PLACE = re.compile(
    r"\b([a-z][a-z0-9]*(?:-[a-z0-9]+)*) (?:§ ?\d|Exp\. ?\d|eqs?\. ?\d|Eqs?\. ?\d|Tables? ?\d|Algorithm ?\d"
    r"|Alg\. ?\d|Theorem ?\d|Scheme ?\d|Fig\. ?\d)")
#: English words that may precede "§ 3", "Table 2", "eq. 5" without naming a paper
NOT_A_KEY = {
    "a", "also", "an", "and", "are", "as", "at", "be", "both", "but", "by", "each", "every", "for", "from", "here",
    "in", "into", "is", "it", "its", "make", "not", "of", "on", "only", "or", "our", "paper", "papers", "per",
    "printed", "s", "same", "see", "so", "than", "that", "the", "their", "then", "this", "thus", "to", "was",
    "where", "which", "with",
}


def user_facing_files() -> list[Path]:
    """Every text file a user of the repository reads (README, docs and the four code rooms)."""
    files = []
    for name in USER_FACING:
        path = ROOT / name
        if path.is_file():
            files.append(path)
        elif path.is_dir():
            files += [p for p in sorted(path.rglob("*")) if p.is_file() and p.suffix in TEXT_SUFFIXES
                      and "__pycache__" not in p.parts and not p.name.startswith(".")]
    return files


def cited_text(path: Path) -> str:
    """The prose of a file: comments and string literals of Python source, everything else whole."""
    text = path.read_text(encoding="utf-8")
    if path.suffix != ".py":
        return text
    parts = []
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type in (tokenize.COMMENT, tokenize.STRING) or tok.type == getattr(tokenize, "FSTRING_MIDDLE", -1):
            parts.append(tok.string)
    return "\n".join(parts)


def defined_keys() -> set[str]:
    return set(DEFINED_KEY.findall(REFERENCES.read_text(encoding="utf-8")))


def test_user_facing_text_points_nowhere_outside_the_repository():
    files = user_facing_files()
    assert any(p.suffix == ".py" for p in files) and (ROOT / "README.md") in files
    hits = []
    for path in files:
        for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if OUTSIDE.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:120]}")
    assert not hits, ("user-facing text points to files a clone does not have (put what a user needs in "
                      "docs/ and point there):\n" + "\n".join(hits))


def test_the_outside_pattern_catches_what_it_should():
    for bad in ("the design is in DESIGN.md of the project's shared folder", "see ../shared/DESIGN.md",
                "parameters from the papers in shared/papers", 'DESIGN "Metrics"'):
        assert OUTSIDE.search(bad), bad
    for fine in ("else ``../shared/data`` beside the checkout", "the shared per-channel actor", "designed"):
        assert not OUTSIDE.search(fine), fine


def test_references_define_the_five_papers_with_dois():
    text = REFERENCES.read_text(encoding="utf-8")
    keys = defined_keys()
    assert {"madrl", "pf-nn", "dtvirm", "federated", "imm-arkf", "util"} <= keys
    entries = re.split(r"\n(?=\s*-\s+\*\*\[)", text)
    for key in ("madrl", "pf-nn", "dtvirm", "federated", "imm-arkf", "util"):
        entry = next(e for e in entries if e.lstrip().startswith(f"- **[{key}]**"))
        assert re.search(r"DOI\s+\[?10\.\d{4,9}/", entry), f"[{key}] has no DOI"
        assert re.search(r"\b(19|20)\d\d\b", entry), f"[{key}] has no year"
    assert len(re.findall(r"^\s*-\s+\*\*\[", text, re.M)) == len(keys), "a reference key is defined twice"


def test_every_cited_key_is_in_the_references():
    keys = defined_keys()
    unknown = []
    for path in user_facing_files():
        prose = cited_text(path)
        for key in CITED_KEY.findall(prose):
            if key not in keys and key not in NOT_A_CITATION and f"[/{key}]" not in prose:  # rich markup
                unknown.append(f"{path.relative_to(ROOT)}: [{key}]")
        for key in CITED_PLACE.findall(prose):
            if key not in keys and key not in NOT_A_KEY:
                unknown.append(f"{path.relative_to(ROOT)}: {key} (cited by section/table/equation)")
    assert not unknown, ("cited but not defined in docs/references.md (add the reference, or, for an English "
                         "word before 'Table 3' and the like, extend NOT_A_KEY):\n" + "\n".join(sorted(set(unknown))))


def test_citation_forms_are_recognised():
    assert CITED_KEY.findall("the trust of [madrl], and x[idx], [text](link.md), list[str], .[dev]") == ["madrl"]
    assert CITED_PLACE.findall("madrl §2.3, pf-nn Table 4, dtvirm eq. 38 and federated Scheme 2") == [
        "madrl", "pf-nn", "dtvirm", "federated"]


def _doc_pages() -> list[Path]:
    """The hand-written pages (docs/*.md); docs/tasks and docs/reproduce are generated."""
    return sorted(DOCS.glob("*.md"))


def test_docs_links_resolve():
    pages = _doc_pages() + [ROOT / "README.md"]
    broken = []
    for page in pages:
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text(encoding="utf-8")):
            if re.match(r"[a-z]+:", target) or target.startswith("#"):
                continue
            path = (page.parent / target.split("#", 1)[0]).resolve()
            if not path.exists():
                broken.append(f"{page.relative_to(ROOT)} → {target}")
    assert not broken, "broken links:\n" + "\n".join(broken)


def test_docs_index_and_readme_link_every_page():
    index = (DOCS / "index.md").read_text(encoding="utf-8")
    for page in _doc_pages():
        if page.name != "index.md":
            assert f"]({page.name})" in index, f"docs/index.md does not link {page.name}"
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "docs/index.md" in readme and "docs/references.md" in readme


def _module_file(parts: list[str]) -> Path | None:
    base = ROOT.joinpath(*parts)
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def test_docs_name_modules_and_files_that_exist():
    missing = []
    for page in _doc_pages():
        text = page.read_text(encoding="utf-8")
        for dotted in set(re.findall(r"\bswarmloc\.(?:envs|agents|bench|leaderboard)(?:\.\w+)+", text)):
            parts = dotted.split(".")[1:]
            # the longest module prefix, then at most one attribute defined in it
            for cut in range(len(parts), 0, -1):
                module = _module_file(parts[:cut])
                if module is not None:
                    break
            rest = parts[cut:]
            source = module.read_text(encoding="utf-8") if module is not None else ""
            ok = module is not None and (not rest or (len(rest) == 1 and re.search(
                rf"^\s*(?:def|class)\s+{rest[0]}\b|^\s*{rest[0]}\s*[:=]|\bimport\b.*\b{rest[0]}\b", source, re.M)))
            if not ok:
                missing.append(f"{page.name}: {dotted}")
        for path in set(re.findall(r"`((?:envs|agents|bench|leaderboard|docs|tests)/[\w./-]*)`", text)):
            if not (ROOT / path.rstrip("/")).exists():
                missing.append(f"{page.name}: {path}")
    assert not missing, "docs name modules or files that do not exist:\n" + "\n".join(sorted(missing))


def test_task_table_matches_the_catalogue():
    from swarmloc.envs.tasks.catalogue import CATALOGUE, get_spec

    text = (DOCS / "tasks.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| \[`(swarmloc/[\w-]+)`\]\(tasks/(\w+)\.md\) \| (\d+) \| (\d+) \| ([\d.]+) \| (\d+) \|",
                      text, re.M)
    assert sorted(r[0] for r in rows) == sorted(CATALOGUE), "docs/tasks.md must list every registered task once"
    for task_id, page, n, n_l, dt, n_t in rows:
        spec = get_spec(task_id)
        assert (int(n), int(n_l), float(dt), int(n_t)) == (spec.n_uav, spec.n_channels, spec.dt, spec.n_steps), \
            f"docs/tasks.md row of {task_id} disagrees with its spec"
        assert (DOCS / "tasks" / f"{page}.md").is_file()


def test_citation_cff_describes_this_package():
    cff = (ROOT / "CITATION.cff").read_text(encoding="utf-8")
    # the [project] table's version (tomllib needs Python 3.11; the package supports 3.10)
    project = (ROOT / "pyproject.toml").read_text(encoding="utf-8").split("[project]", 1)[1].split("\n[", 1)[0]
    version = re.search(r'^version\s*=\s*"([^"]+)"', project, re.M).group(1)
    fields = dict(re.findall(r"^([a-z-]+):[ \t]*(\S.*)?$", cff, re.M))
    assert fields["cff-version"] == "1.2.0"
    assert fields["version"] == version
    assert fields["license"] == "MIT"
    assert "title" in fields and "abstract" in fields and "keywords" in fields and "authors" in fields
    assert "name: The swarmloc developers" in cff
    for doi in ("10.3390/s26123747", "10.3390/computers15030172", "10.3390/drones10010049", "10.3390/s23218823",
                "10.70322/dav.2025.10018"):
        assert f"doi: {doi}" in cff, f"CITATION.cff references lack {doi}"
    assert "\t" not in cff, "YAML forbids tabs in indentation"


@pytest.mark.parametrize("page", ["reward.md", "world.md"])
def test_quoted_constants_are_the_code_defaults(page):
    from swarmloc.envs.world.cost import DEFAULT_PROFILE, PREDICT_FLOPS, RANGE_ROW_FLOPS, VECTOR_ROW_FLOPS
    from swarmloc.envs.world.reward import STANDARD_WEIGHTS
    from swarmloc.envs.tasks.specs import FilterSettings

    text = (DOCS / page).read_text(encoding="utf-8")
    if page == "reward.md":
        w = STANDARD_WEIGHTS
        assert f"(λ1, λ2, λ3) = ({w.delay:g}, {w.energy:g}, {w.jitter:g})" in text
        assert f"σ_acc = {w.sigma_acc:g} m" in text and f"T_max = {w.t_max * 1e3:g} ms" in text
        assert f"{DEFAULT_PROFILE.effective_flops / 1e6:g} MFLOP/s" in text and f"{DEFAULT_PROFILE.power_w:g} W" in text
        assert f"{PREDICT_FLOPS} + 9 · {RANGE_ROW_FLOPS} = {PREDICT_FLOPS + 9 * RANGE_ROW_FLOPS} FLOPs" in text
    else:
        f = FilterSettings()
        assert f"α > α_th ({f.alpha_th:g})" in text and f"α_min = {f.alpha_min:g}" in text
        assert f"{PREDICT_FLOPS} per" in text and f"{RANGE_ROW_FLOPS} per range row" in text
        assert f"{VECTOR_ROW_FLOPS} per row of a 3-vector channel" in text
