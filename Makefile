# Two commands on a fresh machine: `make demo` and `make test`; each builds .venv when missing.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test bench clean clean-cache

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/occmap demo --out demo_output

test: $(STAMP)
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_geometry.py
	$(BIN)/python benchmarks/bench_grid2d.py

clean: clean-cache
	rm -rf $(VENV) demo_output

# Numba's compiled-kernel cache lives beside the sources; clear it after editing kernels if a
# stale entry misbehaves (its validity check is the source file's timestamp and size).
clean-cache:
	find src -name '*.nbi' -delete -o -name '*.nbc' -delete
