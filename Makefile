# Every target creates the virtual environment on first use and reuses it afterwards.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: test install clean-venv

install: $(STAMP)

# torch is pinned on the command line too: pip must take the CPU wheel that is on this machine.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet torch==2.13.0 -e '.[test]'
	touch $(STAMP)

test: $(STAMP)
	NUMBA_CACHE_DIR=$(CURDIR)/$(VENV)/numba-cache $(PY) -m pytest -q tests

clean-venv:
	rm -rf $(VENV)
