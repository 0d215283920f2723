"""Parameter ranges: checks, messages and ranged dataclass fields."""

import math
from dataclasses import dataclass

import numpy as np
import pytest

from dolfin_mpm.params import Parameter, Range, check_fields, check_range, parameter, parameters


@pytest.mark.parametrize(
    "r, text",
    [(Range(0.0, math.inf, "Pa"), "must be > 0 Pa"),
     (Range(0.0, math.inf, closed=(True, False)), "must be >= 0"),
     (Range(0.0, 90.0, "degrees"), "must be in (0, 90) degrees"),
     (Range(0.0, 90.0, "degrees", (True, False)), "must be in [0, 90) degrees"),
     (Range(-1.0, 0.5), "must be in (-1, 0.5)"),
     (Range(0.0, math.inf, "1/s", (False, True)), "must be in (0, inf] 1/s")],
)  # fmt: skip
def test_describe(r, text):
    assert r.describe() == text


def test_contains_and_check():
    r = Range(0.0, 90.0, "degrees", (True, False))
    assert r.contains(0.0) and r.contains(89.9) and r.contains(np.float64(1.0))
    assert not any(r.contains(v) for v in (90.0, -1e-300, math.nan, None, "30"))
    r.check("phi", 30)
    with pytest.raises(ValueError, match=r"^phi must be in \[0, 90\) degrees, got 120$"):
        r.check("phi", 120)
    with pytest.raises(ValueError, match=r"^E must be in \(0, inf\) Pa, got nan$"):
        Range(0.0, math.inf, "Pa").check("E", math.nan)


def test_check_range_keeps_its_signature_and_wording():
    check_range("flip", 1.0, 0.0, 1.0, closed=(True, True))
    with pytest.raises(ValueError, match=r"^courant must be in \(0, 1\], got 0.0$"):
        check_range("courant", 0.0, 0.0, 1.0, closed=(False, True))
    with pytest.raises(ValueError, match=r"^dt must be in \(0, inf\), got -1$"):
        check_range("dt", -1, 0.0, np.inf)


@dataclass(frozen=True)
class _Soil:
    phi: float = parameter(0.0, 90.0, "degrees")
    name: str = "sand"  # not ranged
    c: float = parameter(0.0, math.inf, "Pa", closed=(True, False), default=0.0)
    psi: float | None = parameter(0.0, 90.0, "degrees", closed=(True, True), default=None)

    def __post_init__(self):
        check_fields(self)


def test_ranged_fields():
    assert parameters(_Soil) == {
        "phi": Parameter(Range(0.0, 90.0, "degrees"), None, True),
        "c": Parameter(Range(0.0, math.inf, "Pa", (True, False)), 0.0, False),
        "psi": Parameter(Range(0.0, 90.0, "degrees", (True, True)), None, False),
    }
    assert parameters(_Soil(30.0)) == parameters(_Soil)
    _Soil(30.0, psi=None)  # an optional field may be left unset
    for kwargs, message in (({"phi": 120}, "phi must be in (0, 90) degrees, got 120"),
                            ({"phi": 30.0, "c": -1.0}, "c must be in [0, inf) Pa, got -1.0"),
                            ({"phi": 30.0, "psi": 91.0}, "psi must be in [0, 90] degrees, got 91.0"),
                            ({"phi": None}, "phi must be in (0, 90) degrees, got None")):  # fmt: skip
        with pytest.raises(ValueError) as info:
            _Soil(**kwargs)
        assert str(info.value) == message
