#!/usr/bin/env bash
# Debian 12 environment: DOLFINx 0.5.2 from Debian, a venv of the system Python that sees
# Debian's compiled packages, and an editable install of dolfin_mpm. Idempotent and quick
# when everything is already there.
set -euo pipefail
VENV=${1:-.venv}
PKGS="python3-dolfinx-real openmpi-bin python3-scipy python3-h5py python3-h5py-mpi python3-meshio python3-matplotlib python3-pytest python3-hypothesis python3-venv python3-pip"

bash "$(dirname "$0")/debian-packages.sh" $PKGS

if [ ! -x "$VENV/bin/python" ]; then
  /usr/bin/python3 -m venv --system-site-packages "$VENV"
fi
# No build isolation and no dependencies: numpy, scipy, h5py stay Debian's.
"$VENV/bin/python" -m pip install -q --no-build-isolation --no-deps -e . 2>&1 | grep -v -i warning || true
"$VENV/bin/python" -c "import dolfin_mpm, dolfinx; print('dolfin_mpm on DOLFINx', dolfinx.__version__)"
