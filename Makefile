# avard: `make demo` and `make test` work on a fresh Debian / Raspberry Pi OS with Python 3.11+.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python

.PHONY: demo test lint bench clean

$(VENV)/bin/python:
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
	  { echo "avard needs Python 3.11 or newer (found $$($(PYTHON) --version))"; exit 1; }
	@$(PYTHON) -m venv $(VENV) || \
	  { echo "could not create $(VENV): on Debian install it with 'sudo apt install python3-venv'"; exit 1; }
	$(PY) -m pip install -q --upgrade pip

$(VENV)/.installed-run: pyproject.toml setup.py core/allan/_kernels.c core/io/_framescan.c | $(VENV)/bin/python
	$(PY) -m pip install -q -e '.[plot]'
	@touch $@

$(VENV)/.installed-test: pyproject.toml setup.py core/allan/_kernels.c core/io/_framescan.c | $(VENV)/bin/python
	$(PY) -m pip install -q -e '.[test,plot,web,fleet]'
	@touch $@ $(VENV)/.installed-run

demo: $(VENV)/.installed-run
	$(VENV)/bin/avard demo

test: $(VENV)/.installed-test
	$(VENV)/bin/ruff check .
	$(PY) -m mypy core daemon
	$(PY) -m pytest -n 2 -q

lint: $(VENV)/.installed-test
	$(VENV)/bin/ruff check .
	$(PY) -m mypy core daemon

bench: $(VENV)/.installed-test
	$(PY) -m benchmarks

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache core/allan/_kernels*.so core/io/_framescan*.so
