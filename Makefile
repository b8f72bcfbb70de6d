# Two commands do all the set-up on a fresh machine:
#   make demo   creates .venv, installs the package, compiles the kernels, runs the main job
#   make test   creates .venv, installs the package, runs every test
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed

.PHONY: demo test lint bench clean

$(STAMP): pyproject.toml Makefile
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	# The local CPU wheel; any other torch spec pulls gigabytes of CUDA packages.
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e ".[dev,baselines,ray]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/softarm warmup
	$(BIN)/softarm demo

test: $(STAMP)
	$(BIN)/softarm warmup
	$(BIN)/python -m pytest -q -n 2 --dist loadfile

lint: $(STAMP)
	$(BIN)/ruff check solver softarm_gym baselines tests

bench: $(STAMP)
	$(BIN)/softarm bench

clean:
	rm -rf $(VENV) .pytest_cache
	find . -name __pycache__ -prune -exec rm -rf {} +
