# Two commands for users: `make demo` and `make test`. Each sets up what is missing.
VENV      ?= .venv
VENV_PYPI ?= .venv-pypi
PY        := $(VENV)/bin/python
PY_PYPI   := $(VENV_PYPI)/bin/python
PYTEST_ARGS ?=
MPI_RANKS ?= 2
MPI_TESTS := tests/test_parallel.py tests/test_walls.py tests/test_aggregation.py

.PHONY: demo docs docker conda test test-pypi test-mpi test-mpi-pypi bench lint paraview-check setup setup-pypi clean

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

# The parallel tests under mpirun (Debian's Open MPI; root needs its two confirmations).
test-mpi: $(VENV)/.ready
	OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 mpirun -n $(MPI_RANKS) --oversubscribe \
		$(PY) -m pytest -q -p no:cacheprovider $(MPI_TESTS)

test-mpi-pypi: $(VENV_PYPI)/.ready
	$(VENV_PYPI)/bin/mpiexec -n $(MPI_RANKS) $(PY_PYPI) -m pytest -q -p no:cacheprovider $(MPI_TESTS)

bench: $(VENV)/.ready
	$(PY) benchmarks/step_throughput.py

# The container (Debian 12's DOLFINx; the build runs a short silo as its check) and the
# conda-forge environment (DOLFINx 0.11); neither is built by CI, which has no engine nor conda.
docker:
	docker build -t dolfin_mpm .

conda:
	conda env create -f environment.yml

# The documentation: Sphinx with its tools from docs/requirements.txt; any warning fails it.
docs: $(VENV)/.ready
	$(PY) -m pip install -q -r docs/requirements.txt
	$(PY) -m sphinx -W --keep-going -b html docs docs/_build/html

lint: $(VENV)/.ready
	$(PY) -m pip install -q ruff
	$(PY) -m ruff check . && $(PY) -m ruff format --check .

clean:
	rm -rf $(VENV) $(VENV_PYPI) results .pytest_cache
