"""The wrench's geometry: where its marker is with the wrench upright on a bolt is what the
localization's bolt end takes back to that bolt (the station files' checks rely on it)."""

from __future__ import annotations

import numpy as np
import pytest

from stationd.geometry.tool import BoltEnd, ToolGeometry, bolt_end, marker_upright


@pytest.mark.parametrize("rule", ["axis", "perpendicular"])
def test_the_marker_of_an_upright_wrench_ends_at_its_bolt(rule):
    tool = ToolGeometry(length_mm=300.0, offset_mm=(4.0, -6.0), rule=rule)
    bolt = (1489.8, -529.3, -44.3)
    marker = marker_upright(bolt, tool)
    assert marker == pytest.approx((1485.8, -523.3, -344.3))
    end = bolt_end(np.array(marker), np.array([0.0, 0.0, -1.0]), tool)
    assert isinstance(end, BoltEnd)
    assert end.point_mm == pytest.approx(bolt)
