"""
Declaring node parameters with descriptors: the one helper every helio node uses.

No rclpy import: it takes the node, and builds rcl_interfaces descriptors (description, a
numeric range, a list of allowed strings).
"""

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor


def declare(node, name, default, description, minimum=None, maximum=None, choices=None):
    """
    Declare a parameter with a descriptor and return its value.

    Numbers get a range when `minimum` is given; `choices` lists the allowed strings (named in
    the description, and a value outside them raises ValueError naming the parameter).
    """
    if choices:
        description = f'{description} One of: {", ".join(choices)}.'
    descriptor = ParameterDescriptor(description=description)
    if minimum is not None and isinstance(default, float):
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(minimum), to_value=float(maximum), step=0.0)]
    elif minimum is not None and isinstance(default, int) and not isinstance(default, bool):
        descriptor.integer_range = [IntegerRange(
            from_value=int(minimum), to_value=int(maximum), step=1)]
    value = node.declare_parameter(name, default, descriptor).value
    if choices and value not in choices:
        raise ValueError(f'parameter {name} must be one of {choices}, got {value!r}')
    return value
