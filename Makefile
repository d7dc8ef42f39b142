# Two commands for a fresh machine: `make demo` and `make test` (both create .venv if missing).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
export MUJOCO_GL ?= egl

.PHONY: setup demo test bench clean

$(BIN)/tcot: pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	# CPU torch first, pinned: an open torch requirement could pull a multi-GB CUDA build.
	$(BIN)/python -m pip install -q torch==2.13.0
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $(BIN)/tcot

setup: $(BIN)/tcot

demo: setup
	$(BIN)/tcot run --task goal_cube_on_plate --seed 0 --video runs/demo/demo.mp4 --out runs/demo

test: setup
	$(BIN)/python -m pytest -q

clean:
	rm -rf runs .pytest_cache
