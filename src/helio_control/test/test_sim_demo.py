"""The interim demo paints a dot through the driver clients and writes its outputs."""

from helio_control import sim_demo
from helio_optics.rig_kinematics import default_rig_file
import numpy as np


def test_demo_paints_one_dot_where_it_aimed(tmp_path, capsys):
    status = sim_demo.main(['--out', str(tmp_path), '--dots', '1', '--rig', default_rig_file()])
    output = capsys.readouterr().out
    assert status == 0, output
    assert 'SHORTCUT' in output
    rows = np.loadtxt(tmp_path / 'dots.csv', delimiter=',', comments='#', skiprows=2, ndmin=2)
    target = sim_demo.DEFAULT_DOTS[0]
    assert rows.shape[0] == 1
    assert np.hypot(rows[0, 0] - target[0], rows[0, 1] - target[1]) < 0.5e-3
    assert (tmp_path / 'canvas.png').stat().st_size > 0
