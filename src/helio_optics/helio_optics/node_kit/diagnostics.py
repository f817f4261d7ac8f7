"""diagnostic_msgs helpers: one status per node on the global ``/diagnostics`` topic."""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

OK, WARN, ERROR, STALE = (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR,
                          DiagnosticStatus.STALE)


def diagnostic_array(hardware_id, name, values, stamp, level=OK, message=''):
    """
    Build a DiagnosticArray with one status `name` holding `values` (a flat dict).

    Floats are written with three decimals, everything else with str().
    """
    array = DiagnosticArray()
    array.header.stamp = stamp
    status = DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id)
    status.values = [KeyValue(key=str(k), value=f'{v:.3f}' if isinstance(v, float) else str(v))
                     for k, v in values.items()]
    array.status = [status]
    return array
