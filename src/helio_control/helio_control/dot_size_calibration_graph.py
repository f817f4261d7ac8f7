"""
``helio calibrate dots`` on a running graph (issue 29, item 3): the test row, fit and file.

One PaintPattern goal per N_p target of the test row (``dot_size_calibration.calibration_row``: a
goal holds one N_p target), each into its own run directory; the painter burns the dots,
measures each with the RGB camera and writes its journal. The journals' burnt dots (the
camera's diameter, the dwell) are fitted (``fit_dot_size``) and saved as ``dots.yaml`` in
the painter's ``calibration_dir`` for the rig file it plans with (both asked of the running
painter), where it reads the file at its next goal. The journals are read from the run
directories: the painter must write where this command reads (the simulated graph; a rig
whose painter runs on this machine).
"""

import os

from helio_control.calibration_store import rig_description
from helio_control.camera_calibration_graph import node_parameters
from helio_control.dot_size_calibration import (calibration_row, fit_dot_size,
                                                samples_from_journal, save_dot_calibration)
from helio_control.run_journal import read_journal
from helio_optics.node_kit.deployment import calibration_dir_or_default, rig_file_or_default


def paint_goal(goal_type, test, run_dir):
    """Return the PaintPattern goal of a RowGoal, writing its run into `run_dir`."""
    from geometry_msgs.msg import Point
    goal = goal_type()
    goal.points = [Point(x=float(x), y=float(y), z=0.0) for x, y in test.points]
    goal.n_p_target = test.n_p_target
    goal.offset_x, goal.offset_y = test.offset_x, test.offset_y
    goal.canvas_size = test.canvas_size
    goal.run_dir = run_dir
    goal.fresh = True           # a test dot is burnt where it is asked, never resumed
    return goal


def calibrate_dots_on_graph(graph, client, goal_type, out_dir, goals=None,
                            calibration_dir=None, save=True, timeout=1800.0,
                            progress=lambda text: None):
    """
    Burn the test row through the painter's action `client`; fit and save the calibration.

    Returns (DotSizeCalibration, samples, path saved ('' when not), messages of the goals).
    Raises ``dot_size_calibration.DotCalibrationError`` when the dots cannot be fitted.
    """
    asked = node_parameters(graph, 'painter', ('calibration_dir', 'rig_file'))
    directory = calibration_dir_or_default(calibration_dir or asked.get('calibration_dir'))
    rig_file = rig_file_or_default(asked.get('rig_file') or '')
    samples, messages = [], []
    for test in goals or calibration_row():
        run_dir = os.path.join(os.path.abspath(out_dir), f'n_p_{test.n_p_target}')
        progress(f'{len(test.points)} test dot(s) at N_p {test.n_p_target}')
        response = graph.run_goal(client, paint_goal(goal_type, test, run_dir), None, timeout)
        messages.append(f'N_p {test.n_p_target}: {response.result.message}')
        journal = os.path.join(response.result.run_dir or run_dir, 'journal.jsonl')
        if os.path.exists(journal):
            samples += samples_from_journal(read_journal(journal))
    calibration = fit_dot_size(samples)
    path = save_dot_calibration(directory, calibration, rig_description(rig_file)) \
        if save else ''
    return calibration, samples, path, messages
