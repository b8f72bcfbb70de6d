# Two commands do all the set-up on a fresh machine:
#   make demo   creates .venv, installs the package, runs the main job (compiling only what it uses)
#   make test   creates .venv, installs the package, compiles every kernel in parallel, runs every test
# make docs builds the documentation site into docs/_build/html.
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed

.PHONY: demo test test-long docs lint bench clean

# torch by pip, which takes the local CPU wheel (any other torch spec, and uv, which does not look
# on this disk, pull gigabytes of CUDA packages); the rest by uv, which resolves the same versions
# as pip in less time and keeps the installed torch. Bytecode is compiled at install, as pip does:
# where PYTHONDONTWRITEBYTECODE is set, every process (test workers, subprocesses, Ray workers)
# would otherwise compile torch, Ray and the rest from source on import, 2.4 s each.
$(STAMP): pyproject.toml Makefile
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q torch==2.13.0 uv
	$(BIN)/uv pip install -q --compile-bytecode --python $(BIN)/python -e ".[dev,baselines,ray,docs]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/softarm demo

# The project's bytecode is compiled first, for the same reason as the install's (the workers and
# the processes the tests start load it). The warm-up compiles every kernel once, in parallel
# processes, so that the two test workers load machine code instead of each compiling the same
# kernels. The slowest tests are listed at the end (--durations), so a run shows where its time
# went.
test: $(STAMP)
	$(BIN)/python -m compileall -q solver softarm_gym baselines
	$(BIN)/softarm warmup --quiet
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --durations=25

# Oracles that take minutes each (pytest marker long_oracle; .ci/run runs them after make test).
test-long: $(STAMP)
	$(BIN)/python -m pytest -q -m long_oracle tests

docs: $(STAMP)
	$(BIN)/python -m sphinx -W --keep-going -b html docs docs/_build/html

lint: $(STAMP)
	$(BIN)/ruff check solver softarm_gym baselines tests

bench: $(STAMP)
	$(BIN)/softarm bench

clean:
	rm -rf $(VENV) .pytest_cache docs/_build
	find . -name __pycache__ -prune -exec rm -rf {} +
