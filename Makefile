# The two commands of the set-up contract: `make run` and `make test`.
SHELL   := /bin/bash
PY      ?= python3.11
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed
TSTAMP  := $(VENV)/.installed-test
DSTAMP  := $(VENV)/.installed-docs
HOST    ?= 127.0.0.1
PORT    ?= 8000
PYTEST_ARGS ?=
# three processes on the 2-core machine (the tests wait on browsers, servers and workers: 2 left a third of
# the CPU idle, 4 oversubscribe it; measured 336 s, 378-455 s, 378 s); tests/conftest.py: a file shares a worker,
# and the groups with a slow or browser test go first (--no-loadscope-reorder keeps that order, where xdist would
# hand out the groups with the most tests first and end the run on a long single-test file)
PYTEST_WORKERS ?= 3
# Plugins by name, not every installed one: pytest rewrites the asserts of every module of a package that has
# a plugin entry point (dash, 673 files, imported by open3d), on each run when bytecode is not written.
PYTEST_PLUGINS ?= xdist.plugin,pytest_timeout,_hypothesis_pytestplugin,schemathesis.pytest.plugin
export PYTEST_PLUGINS
# One BLAS / OpenMP thread per process in the suite: its three workers, their sessions' worker processes and
# Chromium already share the two cores, and the libraries' extra threads only spin (measured on the whole suite:
# 562 -> 478 CPU-s of the project's processes, the same 1,271 tests passing). Product runs are unchanged.
# The suite writes bytecode even where PYTHONDONTWRITEBYTECODE is set (this machine's image sets it): pytest keeps
# its rewritten test modules and every process the suite starts (servers, CLIs, dask, workers' forkservers)
# loads the project's modules compiled once (importing the app: 2.0 s of CPU uncompiled, 1.4 s compiled).
TEST_THREADS := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONDONTWRITEBYTECODE=

.PHONY: run test lint docs bench bench-agreement install system-deps clean

$(BIN)/python:
	@command -v $(PY) >/dev/null 2>&1 || PY=python3; $${PY:-$(PY)} -m venv $(VENV) || python3 -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/pip install --quiet -e .
	@touch $@

$(TSTAMP): pyproject.toml | $(BIN)/python
	$(BIN)/pip install --quiet -e ".[test,hardware]"
	@touch $@ $(STAMP)

# open3d needs libusb; the browser tests need Debian's chromium.
system-deps:
	@missing=""; \
	ldconfig -p 2>/dev/null | grep -q libusb-1.0.so.0 || missing="$$missing libusb-1.0-0"; \
	command -v chromium >/dev/null 2>&1 || missing="$$missing chromium"; \
	if [ -n "$$missing" ]; then \
	  echo "installing system packages:$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq $$missing >/dev/null; \
	fi

install: $(STAMP)

run: system-deps $(STAMP)
	$(BIN)/nbv serve --host $(HOST) --port $(PORT)

test: system-deps $(TSTAMP)
	$(BIN)/ruff check planner devices workbench app nbv tests
	@mkdir -p test-output
	@# the log's summary is printed again last: native libraries print at exit after pytest's own summary
	set -o pipefail; $(TEST_THREADS) PYTEST_DISABLE_PLUGIN_AUTOLOAD=1 $(BIN)/python -m pytest -q -rfE -n $(PYTEST_WORKERS) --dist loadgroup --no-loadscope-reorder $(PYTEST_ARGS) 2>&1 \
	  | tee test-output/pytest.log; status=$$?; \
	  echo "== make test: summary (test-output/pytest.log) =="; \
	  grep -aE '^(FAILED|ERROR) |[0-9]+ (passed|failed|errors?)\b.* in [0-9.]+s' test-output/pytest.log | tail -n 60; \
	  exit $$status

$(DSTAMP): pyproject.toml | $(BIN)/python
	$(BIN)/pip install --quiet -e ".[docs]"
	@touch $@ $(STAMP)

# The documentation site (mkdocs.yml): strict, so a broken link or a page left out of the nav fails the build.
docs: $(DSTAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site
	@echo "open site/index.html"

lint: $(TSTAMP)
	$(BIN)/ruff check planner devices workbench app nbv tests
	$(BIN)/ruff format --check planner devices workbench app nbv tests
	$(BIN)/pyright

bench: $(STAMP)
	$(BIN)/python benchmarks/profile_models.py --models ../shared/models --out out/bench --fidelity

bench-agreement: $(STAMP)
	$(BIN)/python benchmarks/search_agreement.py --models ../shared/models --out out/agreement

clean:
	rm -rf $(VENV) out test-output site
