# Two commands for users: `make demo` and `make test`. Each sets up what is missing.
VENV      ?= .venv
VENV_PYPI ?= .venv-pypi
PY        := $(VENV)/bin/python
PY_PYPI   := $(VENV_PYPI)/bin/python
PYTEST_ARGS ?=

.PHONY: demo test test-pypi test-mpi bench lint paraview-check setup setup-pypi clean

$(VENV)/.ready: pyproject.toml scripts/setup-debian.sh
	bash scripts/setup-debian.sh $(VENV)
	touch $@

$(VENV_PYPI)/.ready: pyproject.toml scripts/setup-pypi.sh
	bash scripts/setup-pypi.sh $(VENV_PYPI)
	touch $@

setup: $(VENV)/.ready
setup-pypi: $(VENV_PYPI)/.ready

demo: $(VENV)/.ready
	$(PY) demos/demo_silo.py

test: $(VENV)/.ready
	$(PY) -m pytest -q $(PYTEST_ARGS)

test-pypi: $(VENV_PYPI)/.ready
	$(PY_PYPI) -m pytest -q $(PYTEST_ARGS)

paraview-check: $(VENV)/.ready
	bash scripts/paraview-check.sh $(PY)

bench: $(VENV)/.ready
	$(PY) benchmarks/step_throughput.py

lint: $(VENV)/.ready
	$(PY) -m pip install -q ruff
	$(PY) -m ruff check . && $(PY) -m ruff format --check .

clean:
	rm -rf $(VENV) $(VENV_PYPI) results .pytest_cache
