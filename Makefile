# The two set-up commands of the README: `make run` and `make test`.
# Each creates .venv (Python 3.11+, pip, venv) when missing and installs nurbsdem into it.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test install clean clean-cache

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test,cad,plot,mpi]"
	touch $(STAMP)

# compiles the solver's kernels into numba's cache, so that the first run starts at once
install: $(STAMP)
	$(BIN)/nurbsdem warmup

run: $(STAMP)
	$(BIN)/nurbsdem solve inputs/paper/compaction_quick.inp
	$(BIN)/python postproc/plot_monitors.py inputs/paper/results/quick

# compiles the kernels, then runs the tests in one pytest process per core (tests/run_parallel.py)
test: $(STAMP)
	$(BIN)/python tests/run_parallel.py -q

# Drops every compiled kernel (import nurbsdem already drops those whose sources changed).
clean-cache:
	find nurbsdem -name '*.nbi' -delete -o -name '*.nbc' -delete

clean: clean-cache
	rm -rf $(VENV)
