# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-all install lint bench check-lerobot clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# torch first, pinned: keeps pip from pulling CUDA wheels on a CPU-only machine.
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(PY) -m layerskin_exp.demo

# `make test`: everything but the tests marked slow, in two workers; the real-time and loaded tests
# form one xdist group (tests/conftest.py) and so run one after another in one worker.
# `make test-all`: the slow ones (the loaded soak, a trial from the installed wheel, the damage
# harness, the submitit sweep), one at a time, so the soak's load is the only load it has.
# The two together run every test. Extra pytest arguments: make test PYTEST_ARGS="--durations=0".
# One OpenBLAS thread a process: two workers each spinning two BLAS threads on two cores made a
# finite-element test 7x slower (tests/conftest.py does the same for `pytest -n` run directly).
PYTEST_ARGS ?=
test: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -n 2 --dist loadgroup -m "not slow" $(PYTEST_ARGS)

test-all: $(STAMP)
	$(PY) -m pytest -q -m slow $(PYTEST_ARGS)

lint: $(STAMP)
	$(VENV)/bin/ruff check .

bench: $(STAMP)
	$(PY) -m benchmarks.run all

# LeRobot's own loader on exported datasets, in a venv of its own (docs/export.md):
#   make check-lerobot LEROBOT_CHECK="out/calibration_campaign data/force_calibration"
check-lerobot: $(STAMP)
	$(PY) tools/lerobot_load_check.py $(LEROBOT_CHECK)

clean:
	rm -rf $(VENV) outputs multirun data
