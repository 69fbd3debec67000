# Two commands set everything up on a fresh machine (Python 3.11, make, a C compiler):
#   make demo   -- a short OU simulation and its table
#   make test   -- the default (fast) test suite
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-slow bench reproduce clean

$(STAMP): pyproject.toml constraints.txt
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found (set PYTHON=...)"; exit 2; }
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q -c constraints.txt -e ".[test,plot,dask]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/stochpend simulate --noise ou --D 1 --tau 1 --omega 1 --paths 2000 --t-max 100 --n-times 12 --seed 1

test: $(STAMP)
	$(PY) -m pytest -q -m "not slow"

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow

bench: $(STAMP)
	$(PY) -m benchmarks

reproduce: $(STAMP)
	$(VENV)/bin/stochpend reproduce all --out out/reproduce

clean:
	rm -rf $(VENV) build dist .pytest_cache
