# Two commands for a newcomer (see README):  make render   and   make test
# Both create .venv, install Serenity with its extras, check the headless GL libraries, then act.
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
EXTRAS ?= test,eval,view
comma  := ,
STAMP   = $(VENV)/.installed-$(subst $(comma),-,$(EXTRAS))

.PHONY: setup sysdeps render test test-all bench lint clean

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
	$(BIN)/ruff check serenity tests examples benchmarks

clean:
	rm -rf $(VENV) serenity_out tests/_artifacts .serenity_cache
