"""
Declaring node parameters with descriptors: the one helper every helio node uses.

No rclpy import: it takes the node, and builds rcl_interfaces descriptors (description, a
numeric range, a list of allowed strings). A float default gets a floating-point range, an
int default an integer range (step 1); rclpy then refuses a value outside it, at start-up
(parameter overrides) and in set_parameters.
"""

import math
import numbers

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor


def parameter_descriptor(name, default, description, minimum=None, maximum=None):
    """
    Build the descriptor of parameter `name`: its description and, for a number, its range.

    `minimum` and `maximum` go together, are finite and ordered; a range on a default that is
    not a number (a string, a bool, a list) raises TypeError naming the parameter, rather than
    being dropped.
    """
    descriptor = ParameterDescriptor(description=description)
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


def declare(node, name, default, description, minimum=None, maximum=None, choices=None):
    """
    Declare a parameter with a descriptor and return its value.

    Numbers get a range when `minimum` and `maximum` are given (see `parameter_descriptor`);
    `choices` lists the allowed strings (named in the description, and a value outside them
    raises ValueError naming the parameter).
    """
    if choices:
        description = f'{description} One of: {", ".join(choices)}.'
    descriptor = parameter_descriptor(name, default, description, minimum, maximum)
    value = node.declare_parameter(name, default, descriptor).value
    if choices and value not in choices:
        raise ValueError(f'parameter {name} must be one of {choices}, got {value!r}')
    return value
