"""
Declaring node parameters with descriptors: the one helper every helio node uses.

No rclpy import: it takes the node, and builds rcl_interfaces descriptors (description, a
numeric range, a list of allowed strings, read-only). A float default gets a floating-point
range, an int default an integer range (step 1); rclpy then refuses a value outside it, at
start-up (parameter overrides) and in set_parameters. A number must be finite (issue 35):
rclpy's range check lets NaN through (it compares false with both bounds), so a non-finite
value of a parameter declared here is refused at start-up (ValueError naming it) and in
set_parameters (a reason naming it), range or not.

Read once or read live. A node that reads a parameter only while it starts declares it
read-only (the default here): setting it at run time is refused with a reason instead of
succeeding while changing nothing. A parameter the node reads each time it uses it is
declared with ``dynamic=True``.

Units in names (one rule for every helio package, checked by ``unit_naming_problem``):
a parameter in an unprefixed SI unit (m, s, rad, Hz, kg, W, J, Pa; temperatures in degC as
in the messages) carries no unit in its name (``timeout``, ``focal_length``,
``joint_state_rate``); a parameter in any other unit names it as a suffix (``latitude_deg``,
``velocity_ratio_percent``, ``min_pulse_us``, ``xyz_velocity_mmps``). The description
always ends with the unit in brackets.
"""

import math
import numbers
import re

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

# Name endings that spell an unprefixed SI unit, which the naming rule leaves out.
SI_UNIT_SUFFIXES = ('s', 'm', 'hz', 'rad', 'kg', 'w', 'j', 'pa', 'k', 'c', 'sec', 'secs',
                    'seconds', 'meters', 'metres')
_SI_SUFFIX = re.compile(r'(?<!_per)_(%s)$' % '|'.join(SI_UNIT_SUFFIXES))   # not us_per_s


def unit_naming_problem(name):
    """
    Return why parameter `name` breaks the unit naming rule (module docstring), or ''.

    Only the last component of a dotted name is checked (``site.elevation``).
    """
    last = name.rsplit('.', 1)[-1].lower()
    match = _SI_SUFFIX.search(last)
    if match:
        return (f'parameter {name!r} names the SI unit {match.group(1)!r}: SI units are not '
                f'named (use {name[:len(name) - len(match.group(0))]!r}), other units are')
    return ''


def parameter_descriptor(name, default, description, minimum=None, maximum=None,
                         read_only=False):
    """
    Build the descriptor of parameter `name`: its description and, for a number, its range.

    `minimum` and `maximum` go together, are finite and ordered; a range on a default that is
    not a number (a string, a bool, a list) raises TypeError naming the parameter, rather than
    being dropped.
    """
    descriptor = ParameterDescriptor(description=description, read_only=bool(read_only))
    if minimum is None and maximum is None:
        return descriptor
    if minimum is None or maximum is None:
        raise ValueError(f'parameter {name}: give both minimum and maximum, got '
                         f'{minimum!r} and {maximum!r}')
    if not all(isinstance(bound, numbers.Real) and math.isfinite(bound)
               for bound in (minimum, maximum)) or minimum > maximum:
        raise ValueError(f'parameter {name}: range [{minimum!r}, {maximum!r}] is not two '
                         'finite numbers, lowest first')
    if isinstance(default, bool) or not isinstance(default, (int, float)):
        raise TypeError(f'parameter {name}: a range needs an int or float default, got '
                        f'{type(default).__name__} {default!r}')
    if isinstance(default, float):
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(minimum), to_value=float(maximum), step=0.0)]
    else:
        if minimum != int(minimum) or maximum != int(maximum):
            raise ValueError(f'parameter {name}: an integer range needs whole bounds, got '
                             f'[{minimum!r}, {maximum!r}]')
        descriptor.integer_range = [IntegerRange(
            from_value=int(minimum), to_value=int(maximum), step=1)]
    return descriptor


def declare(node, name, default, description, minimum=None, maximum=None, choices=None,
            dynamic=False):
    """
    Declare a parameter with a descriptor and return its value.

    Numbers get a range when `minimum` and `maximum` are given (see `parameter_descriptor`);
    `choices` lists the allowed strings (named in the description, and a value outside them
    raises ValueError naming the parameter). Without `dynamic` the parameter is read-only
    after start-up (module docstring). A name that breaks the unit naming rule raises
    ValueError.
    """
    problem = unit_naming_problem(name)
    if problem:
        raise ValueError(problem)
    if choices:
        description = f'{description} One of: {", ".join(choices)}.'
    descriptor = parameter_descriptor(name, default, description, minimum, maximum,
                                      read_only=not dynamic)
    if isinstance(default, list) and not default:
        # An empty list says nothing of its element type: declare it as a list of floats.
        from rclpy.parameter import Parameter
        value = node.declare_parameter(name, Parameter.Type.DOUBLE_ARRAY, descriptor).value
        return [] if value is None else [float(v) for v in value]
    value = node.declare_parameter(name, default, descriptor).value
    if choices and value not in choices:
        raise ValueError(f'parameter {name} must be one of {choices}, got {value!r}')
    problem = non_finite_problem(name, value)
    if problem:
        raise ValueError(problem)
    if dynamic:
        _refuse_non_finite_at_run_time(node)
        if choices:
            node._helio_choices[name] = tuple(choices)
    return value


def non_finite_problem(name, value):
    """Return why `value` of parameter `name` is refused as not finite, or ''."""
    if isinstance(value, float) and not math.isfinite(value):
        return f'parameter {name}: {value} is not a finite number'
    if isinstance(value, (list, tuple)):
        for index, element in enumerate(value):
            if isinstance(element, float) and not math.isfinite(element):
                return (f'parameter {name}: value {index + 1} of {len(value)} is {element}, '
                        'not a finite number')
    return ''


def _refuse_non_finite_at_run_time(node):
    """
    Add, once per node, a set_parameters check that refuses bad values by name.

    NaN and infinities; and for a dynamic parameter declared with `choices`, a string
    outside them (``node._helio_choices``).
    """
    if getattr(node, '_helio_non_finite_check', False):
        return
    from rcl_interfaces.msg import SetParametersResult
    node._helio_choices = {}

    def check(parameters):
        for parameter in parameters:
            problem = non_finite_problem(parameter.name, parameter.value)
            choices = node._helio_choices.get(parameter.name)
            if not problem and choices and parameter.value not in choices:
                problem = (f'parameter {parameter.name} must be one of {choices}, got '
                           f'{parameter.value!r}')
            if problem:
                return SetParametersResult(successful=False, reason=problem)
        return SetParametersResult(successful=True)
    node.add_on_set_parameters_callback(check)
    node._helio_non_finite_check = True


def declare_joint_lookup(node, rest_hold=1.0, rest_after_newest=True):
    """
    Declare how a camera node finds the joints at an image's stamp; return (tolerance, hold).

    ``joint_state_tolerance``: the largest time between an image and the joint states used
    for it; ``joint_rest_hold``: how far from the image a joint at rest is still known
    (``JointStateBuffer.at``'s `rest_hold`; `rest_after_newest` as the node passes it there,
    for the description). Both [s].
    """
    tolerance = declare(node, 'joint_state_tolerance', 0.3,
                        'Largest time between an image and the joint states used for it [s].',
                        0.0, 10.0)
    at_rest = ('equal samples around the image, or the newest two equal for an image newer '
               'than them' if rest_after_newest else 'equal samples around the image; not '
               'for an image newer than every sample, the arm may be moving off')
    hold = declare(
        node, 'joint_rest_hold', rest_hold,
        f'A joint at rest ({at_rest}) is known this far from the image; bridges the gaps a '
        "fast simulated clock leaves between the drivers' wall-clock joint states while the "
        'lens is held still (0: off) [s].', 0.0, 10.0)
    return tolerance, hold
