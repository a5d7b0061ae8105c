# Two entry points for a fresh machine: `make demo` and `make test`. Each builds .venv itself.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
BIN    := $(VENV)/bin
DEMO   ?= demo-out

.PHONY: demo rl-demo test lint bench clean

# Byte-code is written on first import, as Python does by default: some machines set
# PYTHONDONTWRITEBYTECODE, and then every process compiles torch again (suite 7:51 → 13:35).
unexport PYTHONDONTWRITEBYTECODE

# One stamp per dependency set, each command installing only what it runs (`make demo` the
# trainer's packages, `make rl-demo` those and the RL ones, `make test` everything the suite
# reads): rebuilt when pyproject.toml changes. Python 3.11's own pip installs this project, so it
# is not upgraded first (the venv and the upgrade took 12 s). `--no-compile`: pip does not
# byte-compile every installed file (most are never imported); what is imported is compiled
# once, on first import.
EXTRAS_demo := train
EXTRAS_rl   := train,rl
EXTRAS_test := train,test
$(VENV)/.stamp-%: pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --no-compile -e '.[$(EXTRAS_$*)]'
	touch $@

demo: $(VENV)/.stamp-demo
	SC2DATA=$(BIN)/sc2data bash scripts/demo.sh $(DEMO)

# After `make demo`: a narration-shaped MaskablePPO agent from the demo's MEM (4 envs: each ends
# an episode, ~770 macro decisions, so that a curve is drawn; a few minutes),
# evaluated sampled and argmax on 10 episodes (both start sides), beside the reference agents
# (the masked uniform policy, reduced-random, scripted) played once on the same episodes.
rl-demo: $(VENV)/.stamp-rl $(DEMO)/rl-baselines/baselines.json
	$(BIN)/sc2data rl train --reward narration --mem $(DEMO)/run --steps 4096 --envs 4 --out $(DEMO)/rl-narration
	$(BIN)/sc2data rl evaluate $(DEMO)/rl-narration
	$(BIN)/sc2data rl compare $(DEMO)/rl-narration --baselines $(DEMO)/rl-baselines --out $(DEMO)/rl-compare
	$(BIN)/sc2data rl plot $(DEMO)/rl-narration --baselines $(DEMO)/rl-baselines --out $(DEMO)/rl-curves.png

$(DEMO)/rl-baselines/baselines.json: | $(VENV)/.stamp-rl
	$(BIN)/sc2data rl baselines --out $(DEMO)/rl-baselines

# Two processes (pytest-xdist), a test file to each at a time: module fixtures are built once.
test: $(VENV)/.stamp-test
	$(PY) -m pytest -q -n 2 --dist loadfile

# Ruff with the rules in pyproject.toml ([tool.ruff.lint]); CI runs it before the tests.
lint: $(VENV)/.stamp-test
	$(BIN)/ruff check

bench: $(VENV)/.stamp-demo
	$(PY) benchmarks/bench_env.py

clean:
	rm -rf $(VENV) $(DEMO) build *.egg-info
