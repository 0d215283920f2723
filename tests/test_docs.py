"""The documentation's pages quote the stored studies they are written from."""

import json
from pathlib import Path

DOCS = Path(__file__).resolve().parent.parent / "docs"


def _series(runs, key, scale=1.0, digits=1):
    """``a / b / c`` of one number over the meshes, coarsest first, as the pages print it."""
    return " / ".join(f"{scale * r[key]:.{digits}f}" for r in sorted(runs, key=lambda r: -r["h"]))


def test_convergence_page_quotes_the_silo_studies():
    """The silo's mesh series in docs/convergence.md (default law, local model) are docs/silo.json's."""
    data = json.loads((DOCS / "silo.json").read_text())
    varied = ("shift", "edge_cell", "split")  # the studies that move the mesh
    plain = [
        r
        for r in data["runs"]
        if r["weight"] == "cubic" and r["wall_friction"] == 20 and not any(r.get(k) for k in varied)
    ]
    default = [r for r in plain if r["law"] == data["default_law"] and r["radius"] == 0.005]
    local = [r for r in plain if r["law"] == "local"]
    assert len(default) >= 4 and len(local) >= 3
    page = (DOCS / "convergence.md").read_text()
    quoted = [
        _series(default, "flow_rate"),
        _series(default, "edge_band_width", 1e3),
        _series(default, "wall_band_width", 1e3),
        _series(default, "channel_width", 1e3),
        _series(default, "mean_iterations", digits=2),
        _series(local, "flow_rate"),
    ]
    missing = [s for s in quoted if s not in page]
    assert not missing, f"docs/convergence.md does not quote docs/silo.json's {missing}"
    # The README quotes the default law on the three finest meshes.
    finest = sorted(default, key=lambda r: r["h"])[:3]
    readme = " ".join((DOCS.parent / "README.md").read_text().split())  # lines joined
    quoted = [
        _series(finest, "flow_rate"),
        *(_series(finest, k, 1e3) for k in ("edge_band_width", "wall_band_width")),
    ]
    missing = [s for s in quoted if s not in readme]
    assert not missing, f"README.md does not quote docs/silo.json's {missing}"
