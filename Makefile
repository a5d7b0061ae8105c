# Two entry points for a fresh machine: `make demo` and `make test`. Each builds .venv itself.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
BIN    := $(VENV)/bin
DEMO   ?= demo-out

.PHONY: demo rl-demo test bench clean

# Byte-code is written on first import, as Python does by default: some machines set
# PYTHONDONTWRITEBYTECODE, and then every process compiles torch again (suite 7:51 → 13:35).
unexport PYTHONDONTWRITEBYTECODE

# One stamp per dependency set: rebuilt when pyproject.toml changes. Python 3.11's own pip
# installs this project, so it is not upgraded first (the venv and the upgrade took 12 s).
# `--no-compile`: pip does not byte-compile every installed file (most are never imported);
# what is imported is compiled once, on first import.
$(VENV)/.stamp: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --no-compile -e '.[train,test]'
	touch $@

demo: $(VENV)/.stamp
	SC2DATA=$(BIN)/sc2data bash scripts/demo.sh $(DEMO)

# After `make demo`: a narration-shaped MaskablePPO agent from the demo's MEM (a few minutes).
rl-demo: $(VENV)/.stamp
	$(BIN)/sc2data rl train --reward narration --mem $(DEMO)/run --steps 2048 --out $(DEMO)/rl-narration
	$(BIN)/sc2data rl evaluate $(DEMO)/rl-narration --episodes 3
	$(BIN)/sc2data rl plot $(DEMO)/rl-narration --out $(DEMO)/rl-curves.png

# Two processes (pytest-xdist), a test file to each at a time: module fixtures are built once.
test: $(VENV)/.stamp
	$(PY) -m pytest -q -n 2 --dist loadfile

bench: $(VENV)/.stamp
	$(PY) benchmarks/bench_env.py

clean:
	rm -rf $(VENV) $(DEMO) build *.egg-info
