# Two entry points for a fresh machine: `make demo` and `make test`. Each builds .venv itself.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
BIN    := $(VENV)/bin
DEMO   ?= demo-out

.PHONY: demo test bench clean

# One stamp per dependency set: rebuilt when pyproject.toml changes.
$(VENV)/.stamp: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[train,test]'
	touch $@

demo: $(VENV)/.stamp
	SC2DATA=$(BIN)/sc2data bash scripts/demo.sh $(DEMO)

test: $(VENV)/.stamp
	$(PY) -m pytest -q

bench: $(VENV)/.stamp
	$(PY) benchmarks/bench_env.py

clean:
	rm -rf $(VENV) $(DEMO) build *.egg-info
