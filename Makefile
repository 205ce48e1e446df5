# Two commands do everything on a fresh machine:
#   make demo   - simulated pick-and-place demo (writes to out/)
#   make test   - ruff, mypy and the whole pytest suite
# Both install what they need (apt packages, .venv, pip packages) and are idempotent.

SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.hsi-installed
export MUJOCO_GL ?= egl
export PYTHONUNBUFFERED := 1

.PHONY: demo test setup apt lint typecheck pytest clean

demo: setup
	$(VENV)/bin/hsi demo --out out

test: setup lint typecheck pytest

setup: apt $(STAMP)

apt:
	@bash scripts/ensure_apt.sh

$(PY):
	@python3 -m venv $(VENV)
	@$(PY) -m pip install -q --upgrade pip

$(STAMP): pyproject.toml | $(PY)
	@echo "[setup] installing Python packages into $(VENV) (first run takes a minute)"
	@$(PY) -m pip install -q -e ".[dev,hw,ui]" 2>&1 | grep -v "^WARNING: Location" || true
	@$(PY) -c "import hsi_planning, hsi_retarget, hsi_nodes, mujoco, open3d, torch, pykdtree" \
		|| { echo "[setup] import check failed"; exit 1; }
	@touch $(STAMP)

lint:
	@$(VENV)/bin/ruff check src tests benchmarks
	@$(VENV)/bin/ruff format --check src tests benchmarks >/dev/null || \
		{ echo "[lint] run '$(VENV)/bin/ruff format src tests benchmarks'"; exit 1; }

typecheck:
	@$(VENV)/bin/mypy

pytest:
	@$(VENV)/bin/pytest -q tests

clean:
	rm -rf out .mypy_cache .ruff_cache .pytest_cache
