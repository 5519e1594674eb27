# swarmloc: two entry points (see README).
#   make demo   set everything up, evaluate the shipped methods, show the leaderboard
#   make test   set everything up and run the test suite
PY      ?= python3
VENV    ?= .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed

.PHONY: setup test wheel-check demo bench clean docs

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# torch comes first and pinned: on these machines 2.13.0 is a local CPU wheel, while an
# open range would pull several GB of CUDA wheels.
$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

setup: $(STAMP)

# --max-worker-restart=0: with --dist loadfile, xdist 3.8 hangs for good after replacing a
# crashed worker (pytest-xdist #784); a crash must fail the run and name its test instead.
# --durations: the slowest tests, to keep the suite inside its 10-minute budget.
test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --max-worker-restart=0 --durations=25

# The wheel users install, built and used in fresh virtualenvs outside the tree: the core
# install without torch, then [all] (.ci/wheel-check says what it runs; about 3 minutes).
wheel-check: $(STAMP)
	BUILD_PY=$(BIN)/python PY=$(PY) .ci/wheel-check

demo: $(STAMP)
	$(BIN)/swarmloc demo

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[dev,bench]"
	$(BIN)/swarmloc bench speed

# The generated pages (one per task; the README's leaderboard from the shipped results),
# then the site in site/ (mkdocs.yml; --strict: a broken link or anchor fails the build).
docs: $(STAMP)
	$(BIN)/swarmloc docs tasks
	$(BIN)/swarmloc docs readme
	$(BIN)/swarmloc docs tuning
	$(BIN)/python -m mkdocs build --strict

clean:
	rm -rf $(VENV) build *.egg-info
