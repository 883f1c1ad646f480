"""Sensor coordinates (LUMO coords_lumo.csv, Wernitz et al. 2021)."""

import numpy as np
import pytest

from vibroscope.errors import ChannelError
from vibroscope.io.coords import line_coords, read_coords


def test_lumo_coords_by_sensor_number(shared_data):
    chans = [f"/lumo/s{k:02d}.linear_acceleration.x" for k in range(1, 19)]
    sc = read_coords(shared_data / "lumo" / "coords_lumo.csv", chans)
    assert sc.xyz.shape == (18, 3) and sc.from_file
    assert sc.xyz[0].tolist() == [0.0, 0.0, 8.95] and sc.directions[0].tolist() == [1.0, 0.0, 0.0]
    assert sc.directions[1].tolist() == [0.0, 1.0, 0.0]
    m = sc.as_mapping()
    assert m[chans[2]]["xyz"] == (0.0, 0.0, 8.0)


def test_by_channel_name_and_line(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("channel,x,y,z,direction\n/a.x,1,2,3,z\n/b.x,4,5,6,-x\n")
    sc = read_coords(p, ["/b.x", "/a.x"])
    assert sc.xyz.tolist() == [[4, 5, 6], [1, 2, 3]] and sc.directions[0].tolist() == [-1, 0, 0]
    with pytest.raises(ChannelError, match="/c.x"):
        read_coords(p, ["/c.x"])
    lc = line_coords(["/a", "/b", "/c"], spacing=0.5)
    assert lc.as_mapping() is None and np.allclose(lc.xyz[:, 0], [0, 0.5, 1.0])
