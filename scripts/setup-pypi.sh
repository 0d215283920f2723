#!/usr/bin/env bash
# Current DOLFINx from PyPI (dolfinx-solver-real) in its own venv of a Python >= 3.12.
# Exits 3 when no such Python is found. Idempotent.
set -euo pipefail
VENV=${1:-.venv-pypi}

find_python() {
  for cand in "${PYTHON_PYPI:-}" python3.13 python3.12 \
              "$HOME"/.pyenv/versions/3.13*/bin/python3 "$HOME"/.pyenv/versions/3.12*/bin/python3; do
    [ -n "$cand" ] || continue
    exe=$(command -v "$cand" 2>/dev/null) || continue
    "$exe" -c 'import sys; sys.exit(sys.version_info < (3, 12))' 2>/dev/null && { echo "$exe"; return 0; }
  done
  return 1
}

if [ ! -x "$VENV/bin/python" ]; then
  PY=$(find_python) || { echo "No Python >= 3.12 found (set PYTHON_PYPI)"; exit 3; }
  echo "Creating $VENV from $PY"
  "$PY" -m venv "$VENV"
fi
if ! "$VENV/bin/python" -c "import dolfinx_solver, scipy, h5py, meshio, matplotlib, pytest, hypothesis" 2>/dev/null; then
  "$VENV/bin/python" -m pip install -q --upgrade pip
  "$VENV/bin/python" -m pip install -q dolfinx-solver-real scipy h5py meshio matplotlib pytest hypothesis
fi
"$VENV/bin/python" -m pip install -q --no-deps -e . 2>&1 | grep -v -i warning || true
"$VENV/bin/python" -c "import dolfin_mpm, dolfinx; print('dolfin_mpm on DOLFINx', dolfinx.__version__)"
