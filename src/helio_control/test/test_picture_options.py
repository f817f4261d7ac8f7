"""
Each picture option is described once (picture_options) and every other place agrees.

The places: ``PlanOptions`` (names, types, defaults), config/picture.yaml (defaults and a
comment each), the PaintPattern goal's comments (``helio paint --help``), and the generated
options of ``helio preview`` and ``helio sky`` (issue 32).
"""

from dataclasses import fields
import os
import re

from helio_control.action_docs import field_comments, installed_action_text
from helio_control.cli import build_parser
from helio_control.picture_options import CANVAS_OPTIONS, help_line, option_flag, OPTIONS
from helio_control.plan import GOAL_FIELDS, OPTION_CHOICES, PlanOptions
from helio_control.preview import build_parser as preview_parser
from helio_msgs.action import PaintPattern
import pytest
import yaml

PICTURE_YAML = os.path.join(os.path.dirname(__file__), '..', '..', '..', 'config',
                            'picture.yaml')
DEFAULTS = {f.name: f.default for f in fields(PlanOptions)}
NUMBERS = [name for name, value in DEFAULTS.items()
           if isinstance(value, (int, float)) and not isinstance(value, bool)]


def option_help(parser, name):
    """Return the help of the option `name` of `parser` (its ``--x-y`` spelling)."""
    for action in parser._actions:
        if option_flag(name) in action.option_strings:
            return action.help
    raise AssertionError(f'{parser.prog} has no {option_flag(name)}')


def subparser(name):
    return build_parser(PaintPattern)._subparsers._group_actions[0].choices[name]


def test_every_option_has_a_meaning_and_every_number_a_unit():
    assert set(OPTIONS) == set(DEFAULTS)
    for name, doc in OPTIONS.items():
        assert len(doc.quantity) > 5 and len(doc.note) > 5, name
        assert bool(doc.unit) == (name in NUMBERS), f'{name}: unit {doc.unit!r}'
        assert f'[{doc.unit}]' in help_line(name) or not doc.unit
    for name in DEFAULTS:
        if isinstance(DEFAULTS[name], str):
            assert name in OPTION_CHOICES, f'{name} takes a word but lists no choices'


def test_dot_radius_says_what_it_is_with_and_without_a_dot_size_calibration():
    text = help_line('dot_radius')
    assert 'pitch' in text and 'dot-size calibration' in text and 'wide' in text
    assert 'unless n_p_target is given' in text     # sized_options(n_p_given)


def yaml_lines():
    """Return {option: (value text, comment)} of config/picture.yaml's picture section."""
    found = {}
    with open(PICTURE_YAML) as stream:
        for line in stream:
            match = re.match(r'^ {6}(\w+):\s*([^#]*?)\s*(?:#\s*(.*))?$', line)
            if match:
                found[match.group(1)] = (match.group(2), match.group(3) or '')
    return found


def test_the_options_file_has_the_defaults_and_each_numbers_unit():
    with open(PICTURE_YAML) as stream:
        values = yaml.safe_load(stream)['/**']['ros__parameters']['picture']
    assert values == DEFAULTS
    lines = yaml_lines()
    assert set(lines) == set(DEFAULTS)
    for name in NUMBERS:
        assert f'[{OPTIONS[name].unit}]' in lines[name][1], \
            f'config/picture.yaml {name}: {lines[name][1]!r} lacks [{OPTIONS[name].unit}]'


def test_the_goal_carries_the_picture_options_its_comments_begin_with_their_head():
    goal_fields = PaintPattern.Goal.get_fields_and_field_types()
    assert set(GOAL_FIELDS) == set(goal_fields) & set(DEFAULTS)
    comments = field_comments(installed_action_text('helio_msgs', 'PaintPattern'))
    for name in GOAL_FIELDS:
        assert comments[name].startswith(OPTIONS[name].head()), \
            f'PaintPattern {name}: {comments[name]!r} does not begin {OPTIONS[name].head()!r}'


def test_preview_has_one_option_per_picture_option_with_its_help_line():
    parser = preview_parser()
    for name in DEFAULTS:
        assert option_help(parser, name) == help_line(name)
    choices = {name: next(a.choices for a in parser._actions if a.dest == name)
               for name in OPTION_CHOICES}
    assert choices == {name: tuple(allowed) for name, allowed in OPTION_CHOICES.items()}


@pytest.mark.parametrize('arguments, expected', [
    (['--dot-radius', '0.003', '--n-p-target', '20'], {'dot_radius': 0.003, 'n_p_target': 20}),
    (['--no-cooling-wait', '--tone-dot-size'], {'cooling_wait': False, 'tone_dot_size': True}),
    (['--solver-budget', '0.2'], {'solver_budget_s': 0.2}),     # the old spelling, abridged
])
def test_preview_options_given_and_not_given(arguments, expected):
    parsed = vars(preview_parser().parse_args(['sample:logo', *arguments]))
    given = {name: parsed[name] for name in DEFAULTS if parsed[name] is not None}
    assert given == expected


def test_sky_and_paint_show_the_same_descriptions():
    sky = subparser('sky')
    for name in CANVAS_OPTIONS:
        assert option_help(sky, name) == help_line(name)
    paint = subparser('paint')
    for name in GOAL_FIELDS:
        assert option_help(paint, name).startswith(f'{name}: {OPTIONS[name].head()}')
