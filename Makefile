# Two entry points (README): `make demo` and `make test`. Both create .venv on first use and
# install the exact versions of requirements.lock (`make lock` updates it: README, Tests).
PYTHON ?= python3
VENV   ?= .venv
STAMP  := $(VENV)/.installed
LOCK   := requirements.lock

.PHONY: demo test test-quick lint bench lock clean

$(STAMP): pyproject.toml $(LOCK)
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --constraint $(LOCK) pip
	$(VENV)/bin/python -m pip install --quiet --constraint $(LOCK) -e '.[dev]'
	$(VENV)/bin/python -m pip check
	touch $(STAMP)

# The main job, on the embedded default inputs: model self-check, then `hpcosim demo` twice:
# the synthetic person with double support on the multi-contact graph (synthetic take ->
# steps -> the person's gait -> tube -> experiments -> FMU -> co-simulation -> replay,
# out/demo-person/), and the synthetic subject on the paper's two domains, the paper's claims
# judged (synthetic take -> steps -> gait -> tube -> experiments, out/demo/).
demo: $(STAMP)
	$(VENV)/bin/hpcosim model check
	$(VENV)/bin/hpcosim demo --out out/demo-person
	$(VENV)/bin/hpcosim demo --domains paper --out out/demo

# The suite in two phases (README, Tests; docs/tests.md): first every test not marked `serial`
# on pytest-xdist workers, one per core (TEST_WORKERS), the tests of a file together on one
# worker (--dist loadfile; tests/conftest.py groups them and starts the longest first); then
# the `serial` tests (judged against wall-clock time: real-time co-simulation, reply
# deadlines) in one process, with the machine to themselves.  Both phases always run and
# report; the target fails if either fails.  They share one cache of compiled models and
# FMUs, made for this run and removed after it.  --durations: the slowest tests are printed
# with every run (the suite's time is a target).
# `make test-quick`: the same two phases without the tests marked `slow` (the longer end-to-end
# runs: fits, libraries, demos), what a change is checked with before `make test`.
TEST_WORKERS ?= auto
TEST_MARK ?=
test: $(STAMP)
	cache=$$(mktemp -d "$${TMPDIR:-/tmp}/hpcosim-test-cache.XXXXXX") || exit 1; \
	trap 'rm -rf "$$cache"' EXIT; export HPCOSIM_TEST_CACHE="$$cache"; \
	$(VENV)/bin/python -m pytest -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder \
	    -m "not serial $(TEST_MARK)" --durations=15; parallel=$$?; \
	$(VENV)/bin/python -m pytest -m "serial $(TEST_MARK)" --durations=5; serial=$$?; \
	test $$parallel -eq 0 && test $$serial -eq 0

test-quick:
	$(MAKE) test TEST_MARK="and not slow"

# ruff: style, imports and the size and complexity guards; mypy: the six product packages
# (both configured in pyproject.toml: [tool.ruff.lint], [tool.mypy]).  Both always run.
lint: $(STAMP)
	$(VENV)/bin/ruff check .; ruff=$$?; \
	$(VENV)/bin/mypy; mypy=$$?; \
	test $$ruff -eq 0 && test $$mypy -eq 0

# Every benchmark (about 10 min on 2 cores) -> docs/performance.md, generated with the machine,
# the date and the commit (never edited by hand; the prose is docs/performance-notes.md)
bench: $(STAMP)
	$(VENV)/bin/python benchmarks/run_all.py --out docs/performance.md

# Re-resolve every dependency within pyproject's ranges in a scratch venv and write the
# exact versions to requirements.lock; then run `make clean test` and commit both files.
lock:
	rm -rf .venv-lock
	$(PYTHON) -m venv .venv-lock
	.venv-lock/bin/python -m pip install --quiet --upgrade pip
	.venv-lock/bin/python -m pip install --quiet -e '.[dev]'
	( echo "# Exact versions the suite was run with (CPython $$(.venv-lock/bin/python -c 'import platform; print(platform.python_version())'), Linux x86_64)."; \
	  echo "# Installed by make and .ci/run with pip's --constraint; regenerate with 'make lock'."; \
	  .venv-lock/bin/python -m pip freeze --all --exclude-editable | grep -v -i '^hpcosim' \
	) > $(LOCK).tmp
	mv $(LOCK).tmp $(LOCK)
	rm -rf .venv-lock

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
