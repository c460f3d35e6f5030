# Two commands for a fresh machine: `make demo` and `make test`; `make test-fast` for the inner loop (the tests
# not marked montecarlo, measured or slow: pyproject.toml); `make bench [BENCH_ARGS="--quick"]` times the code.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# The tests run in two worker processes (pytest-xdist), a test file to a worker so that its module fixtures are
# computed once; `make test XDIST=` runs them in one process (docs/performance.md, "The tests").
XDIST  ?= -n 2 --dist loadfile

.PHONY: demo test test-fast env bench clean clean-cache

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

env: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/graph-calib demo --out demo-out

test: $(STAMP)
	$(PY) -m pytest -q -x $(XDIST) --durations=15

test-fast: $(STAMP)
	$(PY) -m pytest -q -x $(XDIST) -m "not (montecarlo or measured or slow)" --durations=10

bench: $(STAMP)
	$(PY) benchmarks/run_all.py $(BENCH_ARGS)

clean:
	rm -rf $(VENV) demo-out .pytest_cache build *.egg-info

# numba's compiled kernels (docs/performance.md): a cached kernel is checked against its own file only, so
# after editing a module whose kernels others call or inline (sensor_model.py, rotations.py), delete them all.
clean-cache:
	find graph_calib kf_reference \( -name '*.nbi' -o -name '*.nbc' \) -delete
