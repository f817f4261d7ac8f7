"""The kit's parameter declaration on a real rclpy node (private Context): ranges, read-only."""

import math

from helio_optics.node_kit.parameters import declare, parameter_descriptor
from helio_optics.node_kit.parameters import unit_naming_problem
import pytest
import rclpy
from rclpy.context import Context
from rclpy.exceptions import InvalidParameterValueException
from rclpy.parameter import Parameter


@pytest.fixture
def make_node():
    """Make nodes in a private Context; destroy them and shut it down afterwards."""
    context, nodes = Context(), []

    def make(overrides=()):
        node = rclpy.create_node(f'node_parameters_test_{len(nodes)}', context=context,
                                 parameter_overrides=list(overrides))
        nodes.append(node)
        return node

    rclpy.init(context=context)
    try:
        yield make
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_float_range_is_in_the_descriptor_and_enforced(make_node):
    node = make_node()
    assert declare(node, 'gain', 0.9, 'a gain [-]', 0.01, 2.0, dynamic=True) == 0.9
    descriptor = node.describe_parameter('gain')
    assert descriptor.description == 'a gain [-]'
    assert not descriptor.integer_range
    (span,) = descriptor.floating_point_range
    assert (span.from_value, span.to_value, span.step) == (0.01, 2.0, 0.0)
    assert node.set_parameters([Parameter('gain', value=2.0)])[0].successful
    refused = node.set_parameters([Parameter('gain', value=2.5)])[0]
    assert not refused.successful and refused.reason
    assert not node.set_parameters([Parameter('gain', value=0.0)])[0].successful
    assert node.get_parameter('gain').value == 2.0  # the refused values changed nothing


def test_integer_range_from_an_int_default_steps_by_one(make_node):
    node = make_node()
    assert declare(node, 'rim_points', 64, 'rays [-]', 8, 4096, dynamic=True) == 64
    (span,) = node.describe_parameter('rim_points').integer_range
    assert (span.from_value, span.to_value, span.step) == (8, 4096, 1)
    assert not node.describe_parameter('rim_points').floating_point_range
    assert node.set_parameters([Parameter('rim_points', value=8)])[0].successful
    assert not node.set_parameters([Parameter('rim_points', value=7)])[0].successful
    assert not node.set_parameters([Parameter('rim_points', value=4097)])[0].successful
    assert node.get_parameter('rim_points').value == 8


def test_integer_bounds_given_as_whole_floats_are_accepted(make_node):
    node = make_node()
    declare(node, 'count', 3, 'count [-]', 1.0, 10.0)
    (span,) = node.describe_parameter('count').integer_range
    assert (span.from_value, span.to_value) == (1, 10)


def test_an_override_outside_the_range_is_refused_at_start(make_node):
    node = make_node([Parameter('gain', value=5.0)])
    with pytest.raises(InvalidParameterValueException):
        declare(node, 'gain', 0.9, 'a gain [-]', 0.01, 2.0)


def test_an_override_inside_the_range_is_returned(make_node):
    node = make_node([Parameter('gain', value=1.5)])
    assert declare(node, 'gain', 0.9, 'a gain [-]', 0.01, 2.0) == 1.5


def test_no_range_without_bounds(make_node):
    node = make_node()
    assert declare(node, 'rig_file', '', 'rig YAML') == ''
    assert declare(node, 'period', 5.0, 'period [s]', dynamic=True) == 5.0
    for name in ('rig_file', 'period'):
        descriptor = node.describe_parameter(name)
        assert not descriptor.floating_point_range and not descriptor.integer_range
    assert node.set_parameters([Parameter('period', value=1e9)])[0].successful


def test_choices_are_named_in_the_description_and_checked(make_node):
    node = make_node([Parameter('mode', value='otsu')])
    assert declare(node, 'mode', 'fixed', 'Threshold mode.', choices=('fixed', 'otsu')) == 'otsu'
    assert node.describe_parameter('mode').description == 'Threshold mode. One of: fixed, otsu.'
    bad = make_node([Parameter('mode', value='guess')])
    with pytest.raises(ValueError, match=r"parameter mode must be one of .*'guess'"):
        declare(bad, 'mode', 'fixed', 'Threshold mode.', choices=('fixed', 'otsu'))


@pytest.mark.parametrize('default, minimum, maximum, error, words', [
    (1.0, 0.0, None, ValueError, 'give both minimum and maximum'),
    (1.0, None, 2.0, ValueError, 'give both minimum and maximum'),
    (1.0, 2.0, 0.0, ValueError, 'lowest first'),
    (1.0, 0.0, float('inf'), ValueError, 'finite'),
    (1.0, '0', '2', ValueError, 'finite'),
    (3, 0.5, 10, ValueError, 'whole bounds'),
    ('fixed', 0, 1, TypeError, 'int or float default'),
    (True, 0, 1, TypeError, 'int or float default'),
    ([1.0, 2.0], 0.0, 3.0, TypeError, 'int or float default'),
])
def test_a_range_that_cannot_apply_is_a_clear_error(default, minimum, maximum, error, words):
    with pytest.raises(error, match=words) as raised:
        parameter_descriptor('some.name', default, 'what it is', minimum, maximum)
    assert 'some.name' in str(raised.value)


def test_a_bad_range_declares_nothing(make_node):
    node = make_node()
    with pytest.raises(ValueError):
        declare(node, 'gain', 0.9, 'a gain [-]', 2.0, 0.01)
    assert not node.has_parameter('gain')


def test_a_start_up_parameter_is_read_only_and_a_dynamic_one_is_not(make_node):
    node = make_node([Parameter('rate', value=10.0)])
    assert declare(node, 'rate', 20.0, 'poll rate [Hz]', 0.1, 100.0) == 10.0
    assert declare(node, 'gain', 0.9, 'a gain [-]', 0.01, 2.0, dynamic=True) == 0.9
    assert node.describe_parameter('rate').read_only
    assert not node.describe_parameter('gain').read_only
    refused = node.set_parameters([Parameter('rate', value=50.0)])[0]
    assert not refused.successful and 'read-only' in refused.reason.lower()
    assert node.get_parameter('rate').value == 10.0
    assert node.set_parameters([Parameter('gain', value=1.0)])[0].successful


@pytest.mark.parametrize('value', [math.nan, math.inf, -math.inf])
def test_non_finite_numbers_are_refused_at_start_and_at_run_time_by_name(make_node, value):
    # issue 35: rclpy's range check lets NaN through (it compares false with both bounds),
    # and a parameter without a range takes any float
    node = make_node([Parameter('gain', value=value)])
    with pytest.raises((ValueError, InvalidParameterValueException), match='gain'):
        declare(node, 'gain', 0.9, 'a gain [-]', 0.01, 2.0)
    node = make_node([Parameter('offsets', value=[0.0, value])])
    with pytest.raises(ValueError, match='offsets: value 2 of 2 is .*not a finite number'):
        declare(node, 'offsets', [0.0, 0.0], 'offsets [m]')
    node = make_node()
    assert declare(node, 'bias', 0.0, 'a bias without a range [m]', dynamic=True) == 0.0
    assert declare(node, 'gain', 0.9, 'a gain [-]', 0.01, 2.0, dynamic=True) == 0.9
    for name in ('bias', 'gain'):
        refused = node.set_parameters([Parameter(name, value=value)])[0]
        assert not refused.successful and name in refused.reason, refused.reason
        assert math.isfinite(node.get_parameter(name).value)
    assert node.set_parameters([Parameter('bias', value=0.5)])[0].successful


def test_a_dynamic_choice_outside_its_choices_is_refused_at_run_time_by_name(make_node):
    node = make_node()
    assert declare(node, 'rule', 'never', 'when to do it', choices=('missing', 'never'),
                   dynamic=True) == 'never'
    refused = node.set_parameters([Parameter('rule', value='sometimes')])[0]
    assert not refused.successful
    assert "rule must be one of ('missing', 'never'), got 'sometimes'" in refused.reason
    assert node.get_parameter('rule').value == 'never'
    assert node.set_parameters([Parameter('rule', value='missing')])[0].successful


@pytest.mark.parametrize('name, problem', [
    ('timeout_s', "use 'timeout'"), ('joint_state_rate_hz', "use 'joint_state_rate'"),
    ('site.elevation_m', "use 'site.elevation'"), ('lens.offset_rad', "use 'lens.offset'"),
    ('site.pressure_pa', 'SI unit'), ('temperature_c', 'SI unit')])
def test_si_units_in_names_break_the_naming_rule(make_node, name, problem):
    assert problem in unit_naming_problem(name)
    with pytest.raises(ValueError, match='SI units are not named'):
        declare(make_node(), name, 1.0, 'a quantity')


@pytest.mark.parametrize('name', ['timeout', 'latitude_deg', 'min_pulse_us', 'speed_us_per_s',
                                  'velocity_ratio_percent', 'xyz_velocity_mmps', 'dni',
                                  'marker.side', 'rgb.supersample', 'status'])
def test_names_without_a_unit_or_with_a_non_si_unit_follow_the_rule(name):
    assert unit_naming_problem(name) == ''


def test_an_empty_list_default_is_a_list_of_floats(make_node):
    node = make_node([Parameter('cloud_schedule', value=[1.0, 2.0, 0.5])])
    assert declare(node, 'cloud_schedule', [], 'start, end, factor triples') == [1.0, 2.0, 0.5]
    assert declare(make_node(), 'cloud_schedule', [], 'start, end, factor triples') == []
