# Two commands on a fresh machine: `make demo` and `make test`; each builds .venv when missing.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
SOURCES := $(shell find src -name '*.py')
KERNELS := $(VENV)/.kernels
CLEAR_KERNEL_CACHE := find src -type d -path '*/__pycache__/occmap-*' -prune -exec rm -rf {} +

.PHONY: demo test bench clean clean-cache

# setup.py and the C file: the extension (geometry/_single.c) is built at install
$(STAMP): pyproject.toml setup.py src/occmap/geometry/_single.c
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,bench]'
	touch $(STAMP)

# Compiled kernels are kept per digest of all the sources (occmap._jit), so a change anywhere
# starts an empty cache (the old version's goes by itself): every kernel is then compiled once
# (`occmap warmup`), so that no command, demo or test waits for the compiler.
$(KERNELS): $(SOURCES) $(STAMP)
	$(BIN)/occmap warmup
	touch $@

demo: $(STAMP) $(KERNELS)
	$(BIN)/occmap demo --out demo_output

test: $(STAMP) $(KERNELS)
	$(BIN)/python -m pytest -q

# every benchmark (about half an hour; the whole-town out-of-core build is separate: bench_world.py
# --city); each rewrites its section of BENCHMARKS.md
bench: $(STAMP) $(KERNELS)
	$(BIN)/python benchmarks/bench_geometry.py
	$(BIN)/python benchmarks/bench_grid2d.py
	$(BIN)/python benchmarks/bench_local_map.py
	$(BIN)/python benchmarks/bench_localize.py
	$(BIN)/python benchmarks/bench_startup.py
	$(BIN)/python benchmarks/bench_octree.py
	$(BIN)/python benchmarks/bench_world.py

clean: clean-cache
	rm -rf $(VENV) demo_output

# Numba's compiled-kernel cache lives beside the sources, one folder per version of them
clean-cache:
	$(CLEAR_KERNEL_CACHE)
	rm -f $(KERNELS)
