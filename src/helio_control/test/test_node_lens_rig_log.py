"""The lens planner's port logs a procedure's lines of both severities (rclpy's logger)."""

from types import SimpleNamespace

from helio_control.node_lens_rig import NodeLensRig
import rclpy.logging


def test_a_procedure_may_log_a_warning_after_an_info_line():
    # the sun sweep warns of an azimuth guess that saw no spot, then says where it found one:
    # rclpy's logger raises ValueError when one line of code logs at two severities
    logger = rclpy.logging.get_logger('test_node_lens_rig_log')
    port = NodeLensRig(SimpleNamespace(get_logger=lambda: logger), None)
    for warning in (False, True, False, True):
        port.log(f'a line (warning {warning})', warning=warning)
