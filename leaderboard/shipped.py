"""The shipped reference methods' results, loaded into a store.

``leaderboard/results/standard-v1/<method>.json`` are the results files of the shipped
methods on ``standard-v1``, the default board (written by ``swarmloc evaluate --suite
standard-v1``, one per method; regenerate them with ``python -m swarmloc.leaderboard.shipped
--regenerate [METHOD ...]``); ``leaderboard/results/<method>.json`` are those of the frozen
``standard-v0`` (``--suite standard-v0``). They go into the store through the normal submit
path with ``trust=True`` (no re-run: they are the reference methods) and every other check,
so a fresh clone shows a populated leaderboard. An entry already in the store with the same
results is left as it is; one whose results differ from the shipped file (a release changed
how the method runs, not its name or weights, so its hash is the same) is replaced.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from swarmloc.bench.evaluation.results import load_results
from swarmloc.leaderboard.errors import DuplicateSubmission
from swarmloc.leaderboard.ranking import DEFAULT_SUITE
from swarmloc.leaderboard.store import SHIPPED_REFERENCE_METHODS, LeaderboardStore
from swarmloc.leaderboard.submit import submit

#: the shipped standard-v0 results (frozen with the suite)
RESULTS_DIR = Path(__file__).resolve().parent / "results"
#: the shipped results of each suite
RESULTS_DIRS: dict[str, Path] = {DEFAULT_SUITE: RESULTS_DIR / DEFAULT_SUITE, "standard-v0": RESULTS_DIR}
#: shipped reference methods without standard-v1 results, and why (every other one has them)
WITHOUT_V1_RESULTS: dict[str, str] = {
    "ci-ekf": "anchor-free (dtvirm): every standard-v1 task has absolute references, so it runs none of them "
              "(it runs AnchorFree-v0)",
    "ci-ekf-no-aa": "as ci-ekf",
}


@dataclass(frozen=True)
class ShippedLoad:
    """What ``load_shipped`` did: methods stored now (new, or replacing stale results), already
    present with the same results, and refused (with why)."""

    stored: tuple[str, ...]
    present: tuple[str, ...]
    refused: tuple[tuple[str, str], ...]
    replaced: tuple[str, ...] = ()


def shipped_results(results_dir: Path | None = None) -> list[Path]:
    """The shipped results files of one folder in name order (default: every suite's, ``RESULTS_DIRS`` order)."""
    if results_dir is not None:
        return sorted(results_dir.glob("*.json"))
    return [path for folder in RESULTS_DIRS.values() for path in sorted(folder.glob("*.json"))]


def load_shipped(store: LeaderboardStore, results_dir: Path | None = None) -> ShippedLoad:
    """Store every shipped results file not yet in ``store``, and replace stored ones whose results changed.

    Args:
        store: an open leaderboard store.
        results_dir: where the shipped results files are (default: every suite's folder).

    Returns:
        A ``ShippedLoad`` summary. A file that fails validation is reported, not raised:
        the others still load.
    """
    stored, present, refused, replaced = [], [], [], []
    shipped: dict[str, dict[str, str]] = {}  # suite -> method hash -> results text of its trusted entries
    for path in shipped_results(results_dir):
        results = load_results(path)
        name = results.method.name
        suite = results.suite.name
        if suite not in shipped:
            shipped[suite] = {e.method_hash: e.results_json for e in store.entries(suite) if e.trusted}
        if path.read_text(encoding="utf-8") in shipped[suite].values():  # stored as shipped: nothing to check
            present.append(name)
            continue
        if name not in SHIPPED_REFERENCE_METHODS:
            refused.append((path.name, f"{name!r} is not a shipped reference method"))
            continue
        metadata = {"name": name, "authors": "swarmloc reference", "track": results.method.track,
                    "privileged": results.method.privileged,
                    "description": f"shipped reference method {name!r}"}
        try:
            receipt = submit(path, results.method.entry_point, metadata, trust=True, store=store,
                             replace_reference=True)
        except DuplicateSubmission:
            present.append(name)
        except Exception as err:  # noqa: BLE001 - one bad file must not hide the others
            refused.append((path.name, str(err)))
        else:
            stored.append(name)
            if receipt.entry.method_hash in shipped[suite]:
                replaced.append(name)
    return ShippedLoad(tuple(stored), tuple(present), tuple(refused), tuple(replaced))


def show_leaderboard(out: Path, db_url: str | None = None, console=None) -> Path:
    """The main job's last step: load the shipped results into the store, print the
    leaderboard, write its HTML site (with the suite plots, without per-method plots;
    ``swarmloc leaderboard html`` draws them) to ``out / "leaderboard"``.

    Args:
        out: the demo's output folder.
        db_url: store URL (default: ``SWARMLOC_DB`` or the user data folder).
        console: a rich console (default: a new one).

    Returns:
        The site's ``index.html``.
    """
    from rich.console import Console

    from swarmloc.leaderboard.views import TERMINAL_WIDTH, print_leaderboard, render_html

    if console is None:
        console = Console()
        if not console.is_terminal:  # a pipe or a file: the width the table is laid out for
            console.width = max(console.width, TERMINAL_WIDTH)
    with LeaderboardStore(db_url) as store:
        loaded = load_shipped(store)
        if loaded.stored:
            console.print(f"stored {len(loaded.stored)} shipped results file(s) ({', '.join(RESULTS_DIRS)})"
                          + (f", replacing stale entries of {', '.join(loaded.replaced)}" if loaded.replaced else ""))
        for name, why in loaded.refused:
            console.print(f"[yellow]not stored {name}:[/yellow] {why}")
        print_leaderboard(store, console=console)
        # per-method plots would re-run episodes; the demo has drawn its own already
        index = render_html(store, out / "leaderboard", plots=False)
    console.print(f"leaderboard site: {index}")
    return index


def regenerate(methods: list[str], suite_name: str = DEFAULT_SUITE, workers: int = 2) -> None:
    """Re-evaluate ``methods`` on a suite into its shipped results folder (traces are not kept).

    All methods run in one evaluation, so the references every episode needs (uniform, the
    information bound) are computed once per worker, not once per method.
    """
    from swarmloc.bench.evaluation.results import write_results
    from swarmloc.bench.evaluation.runner import evaluate_methods
    from swarmloc.bench.evaluation.suites import get_suite

    results_dir = RESULTS_DIRS[suite_name]
    results_dir.mkdir(parents=True, exist_ok=True)
    suite = get_suite(suite_name)
    runs = evaluate_methods(methods, suite, workers=workers, trace=False)
    failed = {name: run.failed for name, run in runs.items() if run.failed}
    if failed:
        raise RuntimeError(f"not regenerated, some jobs failed: {failed}")
    for name, run in runs.items():
        write_results(results_dir / f"{name}.json", run.results(suite))


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--regenerate", nargs="*", metavar="METHOD",
                        help="re-evaluate these shipped methods (all of the suite's when none is named)")
    parser.add_argument("--suite", default=DEFAULT_SUITE, choices=list(RESULTS_DIRS))
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    if args.regenerate is not None:
        methods = args.regenerate or sorted(path.stem for path in shipped_results(RESULTS_DIRS[args.suite]))
        regenerate(methods, args.suite, workers=args.workers)


if __name__ == "__main__":
    main()
