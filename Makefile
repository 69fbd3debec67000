# Two commands set everything up on a fresh machine (Python 3.11, make, a C compiler):
#   make demo   -- a short OU simulation and its table
#   make test   -- the default (fast) test suite
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test coverage lint typecheck test-slow test-minimal test-baseline bench reproduce clean

$(STAMP): pyproject.toml constraints.txt
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found (set PYTHON=...)"; exit 2; }
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q -c constraints.txt -e ".[test,plot,dask]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/stochpend simulate --noise ou --D 1 --tau 1 --omega 1 --paths 2000 --t-max 100 --n-times 12 --seed 1

# The lint and type gates (pyproject.toml: [tool.ruff], [tool.mypy]) run first: a finding fails the test.
# --durations: the slowest tests are listed in every run's log, to keep the suite's time watched.
# -n auto: one pytest-xdist worker per core (at most 4), each test file on one worker
# (tests/conftest.py shares the one tiny reproduce), docs/development.md: why, and the times.
test: $(STAMP) lint typecheck
	$(PY) -m pytest -q -m "not slow" -n auto --maxprocesses 4 --dist loadfile --durations=25

# The default suite under coverage.py (slower: Numba's compiler runs traced), then the
# package's line coverage; docs/development.md keeps the last measured numbers.
coverage: $(STAMP)
	$(PY) -m coverage run -m pytest -q -m "not slow" --durations=25
	$(PY) -m coverage report

lint: $(STAMP)
	$(PY) -m ruff check src tests benchmarks

typecheck: $(STAMP)
	$(PY) -m mypy

# The package without its optional extras (no matplotlib, dask or distributed ever installed):
# what needs none works, what needs one says which (CI runs this after make test).
MIN_VENV := .venv-min
MIN_STAMP := $(MIN_VENV)/.installed
MIN_TESTS := tests/system/test_without_extras.py tests/unit/test_public_api.py tests/unit/test_imports.py \
	tests/statistical/test_golden.py tests/unit/test_user_observables.py

$(MIN_STAMP): pyproject.toml constraints.txt
	test -x $(MIN_VENV)/bin/python || $(PYTHON) -m venv $(MIN_VENV)
	$(MIN_VENV)/bin/python -m pip install -q -c constraints.txt -e . pytest hypothesis
	touch $(MIN_STAMP)

test-minimal: $(MIN_STAMP)
	! $(MIN_VENV)/bin/python -c "import matplotlib" 2>/dev/null
	! $(MIN_VENV)/bin/python -c "import dask" 2>/dev/null
	$(MIN_VENV)/bin/python -m pytest -q -m "not slow" -p no:cacheprovider $(MIN_TESTS)

# The golden and lanes tests again as an AVX2-only x86-64 machine computes them: the kernels
# compiled for the x86-64-v3 baseline, numpy's CPU dispatch held to AVX2 (tests/golden/run_baseline.py;
# docs/development.md, "What is bit-identical, and where"). CI runs it after make test.
BASELINE_TESTS := tests/statistical/test_golden.py tests/statistical/test_golden_cuda.py tests/unit/test_lanes.py

test-baseline: $(STAMP)
	$(PY) tests/golden/run_baseline.py -q -p no:cacheprovider -n auto --maxprocesses 4 --dist loadfile $(BASELINE_TESTS)

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow

bench: $(STAMP)
	$(PY) -m benchmarks

reproduce: $(STAMP)
	$(VENV)/bin/stochpend reproduce all --out out/reproduce

clean:
	rm -rf $(VENV) $(MIN_VENV) build dist .pytest_cache

# CUDA registers and spills per kernel for sm_90, compiled offline (no GPU): a separate venv with
# numba-cuda and ptxas (benchmarks/cuda-tools.txt).  make cuda-registers CUDA_ARGS="--lto --out x.md"
CUDA_VENV := .venv-cuda
CUDA_PY := $(CUDA_VENV)/bin/python
CUDA_STAMP := $(CUDA_VENV)/.installed
CUDA_ARGS ?=

.PHONY: cuda-registers cuda-compile-check gpu-check

$(CUDA_STAMP): benchmarks/cuda-tools.txt pyproject.toml constraints.txt
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found (set PYTHON=...)"; exit 2; }
	test -x $(CUDA_PY) || $(PYTHON) -m venv $(CUDA_VENV)
	$(CUDA_PY) -m pip install -q -c constraints.txt -r benchmarks/cuda-tools.txt \
		$$($(CUDA_PY) -c 'import tomllib; print(" ".join(tomllib.load(open("pyproject.toml", "rb"))["project"]["dependencies"]))')
	touch $(CUDA_STAMP)

cuda-registers: $(CUDA_STAMP)
	PYTHONPATH=src $(CUDA_PY) benchmarks/cuda_registers.py $(CUDA_ARGS)

# Every kernel kind the CUDA backend launches (advance, pairs, init, tracked advance, accumulate,
# joint: stochpend.engine.cuda.kernel_variants()) compiled for sm_90 offline, the path a launch
# takes (nvJitLink LTO, then ptxas): no GPU needed; fails on any compile failure. The table of
# registers and spills goes to out/cuda-compile-check.md. CUDA_CHECK=ci: the representative subset
# (every kind, 85 of the 214 kernels) that .ci/run uses; docs/gpu.md, "Developer notes": timings.
CUDA_CHECK ?= all

cuda-compile-check: $(CUDA_STAMP)
	PYTHONPATH=src $(CUDA_PY) benchmarks/cuda_registers.py --lto --subset $(CUDA_CHECK) \
		--out out/cuda-compile-check.md > /dev/null

# On a machine with an NVIDIA GPU: device tests, gpu_bench --record, the closed-moment oracle, the
# family with accumulators, a short reproduce, in one report (benchmarks/gpu_check.py; docs/gpu.md).
# Without a GPU it says so in one line (exit 2). make gpu-check GPU_CHECK_ARGS="--quick"
GPU_CHECK_ARGS ?=

gpu-check: $(CUDA_STAMP)
	$(CUDA_PY) -m pip install -q -c constraints.txt -e ".[test,cuda]"
	$(CUDA_PY) benchmarks/gpu_check.py $(GPU_CHECK_ARGS)
