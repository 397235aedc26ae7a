# The two quick-start commands of the README: `make demo` and `make test`.
PYTHON ?= python3

.PHONY: install demo test bench bench-quick bench-ensemble bench-accuracy stress

install:
	$(PYTHON) -m pip install -q -e '.[test]'

demo: install
	$(PYTHON) examples/demo.py

# on every core, a test file per worker at a time (files share session-scoped builds: FMUs, references)
test: install
	$(PYTHON) -m pytest -q -n auto --dist loadfile

bench: install
	$(PYTHON) -m pip install -q -e '.[bench]'
	$(PYTHON) -m benchmarks.work_precision

bench-quick: install
	$(PYTHON) -m pip install -q -e '.[bench]'
	$(PYTHON) -m benchmarks.work_precision --quick

# ensembles on Dask: members/s on 1 and 2 workers, per-member overhead, cold start (docs/ensemble.md)
bench-ensemble: install
	$(PYTHON) -m benchmarks.bench_ensemble

# accuracy by default: scene x method -> error against the independent reference, the run's estimate, the time with
# and without it (docs/accuracy.md); --quick in CI
bench-accuracy: install
	$(PYTHON) -m benchmarks.accuracy
