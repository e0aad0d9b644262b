# The two commands of the README: `make demo` and `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
ARCH ?= cpu
# pytest-xdist workers: most of a cold test run is Taichi compiling each test's kernels,
# one kernel at a time, so two processes halve it on 2 cores (WORKERS=0: one process)
WORKERS ?= auto
# how Taichi compiles the tests' kernels: COMPILE=fast or optimized (unset: tests/conftest.py
# takes TAICHI_SPHERES_COMPILE, else fast; taichi_spheres/runtime.py COMPILE_MODES)
COMPILE ?=
COMPILE_OPT := $(if $(COMPILE),--compile $(COMPILE))

.PHONY: demo test test-slow bench venv clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --upgrade pip >/dev/null
	$(BIN)/pip install -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	sh tools/ensure_vulkan.sh
	mkdir -p out
	$(BIN)/taichi-spheres run scenes/seed_five.toml -o out/seed_five.mp4 --arch $(ARCH)

test: $(STAMP)
	$(BIN)/python -m pytest -q -n $(WORKERS) --arch $(ARCH) $(COMPILE_OPT)

test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -n $(WORKERS) --arch $(ARCH) $(COMPILE_OPT) --slow

bench: $(STAMP)
	$(BIN)/python tools/bench.py --arch $(ARCH)

clean:
	rm -rf $(VENV) out *.egg-info
