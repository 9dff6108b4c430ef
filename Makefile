# The two commands a new user types: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
WORKERS ?= 2

.PHONY: demo test test-xla-default lint format bench docs clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/jaxcable demo --out demo_out

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/basedpyright
	# Two worker processes (pytest-xdist) share the cores, one file (or notebook) at a
	# time each, the slowest first (tests/conftest.py; --no-loadscope-reorder, or xdist
	# would order the groups by their number of tests), and one compilation cache. Two
	# processes also because late in one long process XLA's CPU compiler crashed
	# (SIGSEGV, SIGABRT) on a fresh clone; each half of the suite alone passes.
	# tests/conftest.py compiles with XLA's faster-compiling CPU emitters when this jaxlib
	# has them, and with the scans' loops as single kernels (as `import jaxcable` sets them
	# up); `make test-xla-default` runs the same suite with XLA's defaults.
	$(BIN)/pytest -q --durations=25 -n $(WORKERS) --dist loadgroup --no-loadscope-reorder tests

test-xla-default: $(STAMP)
	JAXCABLE_TEST_XLA_EMITTERS=default JAXCABLE_TEST_LOOP_KERNELS=off $(BIN)/pytest -q --durations=25 -n $(WORKERS) --dist loadgroup --no-loadscope-reorder tests

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/basedpyright

format: $(STAMP)
	$(BIN)/ruff check --fix .
	$(BIN)/ruff format .

bench: $(STAMP)
	$(BIN)/python benchmarks/kernel.py

# The reference site, into site/ (tests/test_docs.py builds it with --strict in `make test`).
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

clean:
	rm -rf $(VENV) demo_out .pytest_cache site
