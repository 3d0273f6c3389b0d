# The README's two commands (`make demo`, `make test`) do all set-up: they create .venv
# and install the project into it. torch is pinned to the local CPU build by constraints.txt.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
# Second venv with the optional RL tools (rl_zoo3, sb3-contrib, ray[rllib]); ray pins
# gymnasium 1.2.2, so the RL-tool tests run there, on the low end of the gymnasium range
# (only those: the whole envs suite there doubled make test's time).
RLVENV := .venv-rl
RLSTAMP := $(RLVENV)/.installed-stamp

.PHONY: demo test bench venv clean

# After installing, and after an edit of a kernel's source, compile the numba kernels once into
# their caches (spreadgym.warm), so that the first simulation or env step loads them (seconds)
# instead of compiling them (a minute or more; the test workers would each compile them).
WARMSTAMP := $(VENV)/.kernels-stamp
KERNELS := $(wildcard spreadgym/physics/*.py spreadgym/physics/compiled/*.py spreadgym/spread/*.py)

$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --constraint constraints.txt --editable ".[dev]"
	touch $(STAMP)

$(WARMSTAMP): $(STAMP) $(KERNELS)
	$(BIN)/python -m spreadgym.warm
	touch $(WARMSTAMP)

$(RLSTAMP): pyproject.toml constraints.txt
	test -x $(RLVENV)/bin/python || $(PYTHON) -m venv $(RLVENV)
	$(RLVENV)/bin/python -m pip install --quiet --constraint constraints.txt --editable ".[dev,zoo,rllib]"
	touch $(RLSTAMP)

venv: $(WARMSTAMP)

demo: $(WARMSTAMP)
	$(BIN)/spreadgym demo

test: $(WARMSTAMP) $(RLSTAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q -n auto
	$(RLVENV)/bin/python -m pytest -q -n auto tests/envs/test_rl_tools.py

bench: $(WARMSTAMP)
	$(BIN)/spreadgym bench

clean:
	rm -rf $(VENV) $(RLVENV) build *.egg-info
