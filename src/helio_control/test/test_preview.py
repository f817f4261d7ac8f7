"""The preview command writes a readable preview.png and a plan.json of the same plan."""

import json

import cv2
from helio_control.plan import Plan
from helio_control.preview import main
import pytest


@pytest.mark.parametrize('sample, mode', [('text', 'centerline'), ('portrait', 'tones')])
def test_preview_writes_picture_and_plan(tmp_path, capsys, sample, mode):
    out = tmp_path / sample
    assert main([f'sample:{sample}', '--out', str(out), '--feature-mode', mode,
                 '--ordering', 'nearest_2opt']) == 0
    assert 'dots' in capsys.readouterr().out
    preview = cv2.imread(str(out / 'preview.png'))
    assert preview is not None and min(preview.shape[:2]) >= 800
    data = json.loads((out / 'plan.json').read_text())
    plan = Plan.from_json((out / 'plan.json').read_text())
    assert data['mode'] == mode and data['ordering'] == 'nearest_2opt'
    assert data['dot_count'] == len(plan) > 0
    for key in ('time_estimate', 'quality', 'travel_m', 'travel_s', 'n_p_targets'):
        assert key in data


def test_help_exits_zero(capsys):
    with pytest.raises(SystemExit) as stop:
        main(['--help'])
    assert stop.value.code == 0
    assert 'sample:text' in capsys.readouterr().out


def test_unknown_choice_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as stop:
        main(['sample:text', '--feature-mode', 'sketch'])
    assert stop.value.code == 2
