"""The benchmark runs end to end (briefly) and writes flat JSON with units in the keys."""

import json

from helio_drivers import bench


def test_bench_writes_flat_json(tmp_path):
    path = tmp_path / 'bench.json'
    assert bench.main(['--samples', '30', '--poll-seconds', '0.1', '--skip-node',
                       '--json', str(path)]) == 0
    figures = json.loads(path.read_text())
    for key in ('dobot_roundtrip_ms_median', 'dobot_roundtrip_ms_p99', 'dobot_pose_poll_hz',
                'maestro_roundtrip_ms_median', 'client_move_motion_s_mean'):
        assert figures[key] > 0.0
    assert all(isinstance(v, float) for v in figures.values())
    # a 38-byte GetPose reply alone takes 3.3 ms on a 115200 baud line
    assert figures['dobot_roundtrip_115200baud_ms_median'] >= 38 * 10 / 115200 * 1000
