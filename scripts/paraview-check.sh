#!/usr/bin/env bash
# ParaView check: ParaView's own XDMF readers open the main demo's particle and grid series, and
# pvbatch renders the silo at t = 0.25 s coloured by the non-local rate; fails if anything cannot
# be read. Installs ParaView and a virtual X server from Debian when they are missing, and runs
# the main demo when its results are missing.
set -euo pipefail
PY=${1:-.venv/bin/python}
OUT=${2:-results/silo/paraview_silo.png}
RUN=results/silo/runs/h10mm_r5mm_cubic_wall20

bash "$(dirname "$0")/debian-packages.sh" paraview xvfb xauth

[ -f "$RUN/particles.xdmf" ] || "$PY" demos/demo_silo.py
# pvbatch renders through X: a virtual server, open to local clients.
xvfb-run -a -s "-ac -screen 0 1280x1024x24" pvbatch scripts/paraview_render.py "$RUN" "$OUT"
