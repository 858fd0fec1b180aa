# Two commands on a fresh machine (Python >= 3.11, pip, make):
#   make run   -> install into .venv (pinned by constraints.txt) and run the whole pipeline on the bundled data
#   make test  -> install and run the test suite
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
# `make run` installs what the pipeline needs (extras mesh, uq); `make test` adds the test tools (extra test:
# pytest, felupe, snakefmt and the SLURM executor plugin, whose import runs `scontrol show config`, i.e. every
# snakemake command waits up to 10 s on a machine with SLURM's client tools and no reachable controller)
STAMP := $(VENV)/.tissuemech-installed
TEST_STAMP := $(VENV)/.tissuemech-installed-test
CORES ?= all
# numba keys its cache on the source file of each jitted function only; the TLED kernels inline material laws
# from other modules, so the cache folder is named after the numba-compiled sources (a stale kernel is never reused):
# tissuemech.numba_cache, which imports nothing but the standard library, so any python3 computes it before install
ifeq ($(origin NUMBA_CACHE_DIR), undefined)
NUMBA_CACHE_DIR := $(shell PYTHONPATH=src $(PYTHON) -c 'from tissuemech.numba_cache import source_keyed_cache_dir as d; print(d("$(CURDIR)/.numba_cache"))')
endif
export NUMBA_CACHE_DIR
export MPLBACKEND ?= Agg
export HDF5_USE_FILE_LOCKING ?= FALSE

.PHONY: install install-test run test test-fast calibration-ci lint regression-update lock clean

install: $(STAMP)

install-test: $(TEST_STAMP)

# pip writes no bytecode (--no-compile): compiling every installed file (all of scipy, pandas, matplotlib, their
# tests...) was half of the install (51 -> 24 s on the 2-core VM). The modules the jobs import are compiled
# once instead, by importing them with bytecode writing on (WARM_IMPORTS; ~10 s), so that where
# PYTHONDONTWRITEBYTECODE is set (containers, CI) the ~100 job processes do not each compile them again; a module
# missed here is compiled by its first importer, or in every importer where writing is off
WARM_IMPORTS := tissuemech.analysis tissuemech.stages tissuemech.summary tissuemech.uq tissuemech.io.ingest \
	tissuemech.lve tissuemech.tts tissuemech.posterior snakemake.cli snakemake.script statsmodels.api lmfit emcee \
	meshio matplotlib.pyplot
WARM_BYTECODE = env -u PYTHONDONTWRITEBYTECODE $(PY) -c 'import importlib, sys; [importlib.import_module(m) for m in sys.argv[1:]]'

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "Python >= 3.11 required"'
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade "pip>=24"
	$(PY) -m pip install --quiet --no-compile -c constraints.txt -e ".[mesh,uq]"
	$(WARM_BYTECODE) $(WARM_IMPORTS)
	touch $(STAMP)

$(TEST_STAMP): $(STAMP)
	$(PY) -m pip install --quiet --no-compile -c constraints.txt -e ".[test,mesh,uq]"
	$(WARM_BYTECODE) pytest xdist felupe
	touch $(TEST_STAMP)

# the package's bytecode is written once before the ~80 job processes import it: where PYTHONDONTWRITEBYTECODE is
# set (containers, CI) each of them would compile every module it imports again (~0.15 CPU s per job)
# the report (8-12 s of Snakemake's own work) is rebuilt only when a result, log or job benchmark is newer than it:
# a rerun with nothing to do stays a no-op
run: install
	$(PY) -m compileall -q src
	$(VENV)/bin/snakemake --cores $(CORES)
	@if [ ! -f results/report.html ] || [ -n "$$(find results logs benchmarks/runs -type f -newer results/report.html \
		-print -quit 2>/dev/null)" ]; then $(VENV)/bin/snakemake --report results/report.html; \
	else echo "results/report.html is up to date"; fi

# each test process runs the jobs' code as Snakemake runs a one-thread job: one BLAS/OpenMP thread (Snakemake sets
# these to the job's threads). With the library default (a thread per core) the pytest workers' BLAS threads spin
# against each other on small matrices: the brain's diagnosis took 119 CPU s against 48 on the 2-core VM
ONE_THREAD := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1

test: install-test
	$(ONE_THREAD) $(PY) -m pytest -q -n 2 --dist loadgroup --durations=25 -m "not calibration"

# the pipeline-path calibration subset (docs/calibration.md): fresh seeds through analyse_dataset, 12-30 min on 2 cores
calibration-ci: install-test
	$(ONE_THREAD) $(PY) -m pytest -q -n 2 -m calibration tests/diagnosis/test_calibration.py

test-fast: install-test
	$(ONE_THREAD) $(PY) -m pytest -q -m "not slow"

lint: install-test
	$(VENV)/bin/snakefmt --check Snakefile workflow/
	$(VENV)/bin/snakemake -n --quiet

# Regenerate the committed reference table of fitted parameters and show what moved.
regression-update: install
	$(PY) -m tissuemech.regression --update

# Regenerate the pinned constraints from the current environment.
lock: install-test
	$(PY) -m pip freeze --exclude-editable | grep -v '^tissuemech' > constraints.txt

clean:
	rm -rf results logs benchmarks/runs .snakemake .numba_cache
