# Two commands for a newcomer (see README):  make render   and   make test
# Both create .venv, install Serenity with its extras, check the headless GL libraries, then act.
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
EXTRAS ?= test,eval,view
comma  := ,
STAMP   = $(VENV)/.installed-$(subst $(comma),-,$(EXTRAS))

.PHONY: setup sysdeps render test test-all bench lint clean figures figures-quick cycles

$(BIN)/python:
	@$(PYTHON) -m venv $(VENV) 2>/dev/null || { \
	  echo "python3 -m venv is unavailable; using virtualenv instead"; \
	  $(PYTHON) -m pip install -q --user virtualenv && $(PYTHON) -m virtualenv -q $(VENV); }
	$(BIN)/python -m pip install -q --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	PYTHONWARNINGS=ignore $(BIN)/python -m pip install -q -e '.[$(EXTRAS)]'
	@touch $@


sysdeps:
	@sh tools/check_sysdeps.sh

setup: sysdeps $(STAMP)

render: setup
	$(BIN)/serenity render

test: setup
	$(BIN)/python -m pytest

test-all: setup
	$(BIN)/python -m pytest -m ''

lint: setup
	$(BIN)/ruff check serenity tests examples benchmarks tools

# Every headline result JSON in benchmarks/results, its charts, then every table in README.md and
# docs/*.md, one job after another (timings must not share the cores): about an hour on 2 cores from a
# fresh clone, the frontier's two peers (Mitsuba and Cycles) included. figures-quick re-measures the
# timings only (frame, kd-tree, frontier, quick start).
# See benchmarks/README.md; `bash benchmarks/figures.sh list` names the steps.
figures: setup cycles
	bash benchmarks/figures.sh all

figures-quick: setup cycles
	bash benchmarks/figures.sh quick

# Blender Cycles, the frontier's second path tracer (serenity/eval/cycles.py): bpy pins numpy 1.x, so it
# gets a Python of its own, .venv-cycles (bpy 5.0 needs Python 3.11); SERENITY_CYCLES_PYTHON names another.
CYCLES_PYTHON ?= python3.11
CYCLES_VENV   ?= .venv-cycles

cycles:
	@test -x $(CYCLES_VENV)/bin/python || $(CYCLES_PYTHON) -m venv $(CYCLES_VENV)
	$(CYCLES_VENV)/bin/python -m pip install -q --upgrade pip
	$(CYCLES_VENV)/bin/python -m pip install -q 'bpy==5.0.1'
	$(CYCLES_VENV)/bin/python -c "import bpy; print('Blender', bpy.app.version_string, 'in $(CYCLES_VENV)')"

clean:
	rm -rf $(VENV) serenity_out tests/_artifacts .serenity_cache
