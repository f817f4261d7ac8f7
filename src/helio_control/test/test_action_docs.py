"""The actions' own comments as the help of their fields (issue 32)."""

from helio_control.action_docs import field_comments, installed_action_text, listed_choices
from helio_control.cli import goal_options
from helio_control.features import FEATURE_MODES
from helio_control.path_ordering import ORDERINGS
from helio_control.procedures.painter_port import COOLING_RULES
from helio_msgs.action import PaintPattern
import pytest

TEXT = """# a header comment
# --- goal
float64 size        # side [m]
string mode         # "a" or "b" (the
                    # default: "a")
uint8 KIND_A=1      # a constant, not a field
bool flag
---
bool success        # done
---
uint32 index        # [-]
"""


def test_comments_are_read_per_part_with_their_continuations():
    assert field_comments(TEXT) == {'size': 'side [m]', 'mode': '"a" or "b" (the default: "a")',
                                    'flag': ''}
    assert field_comments(TEXT, 'result') == {'success': 'done'}
    assert field_comments(TEXT, 'feedback') == {'index': '[-]'}
    assert listed_choices(field_comments(TEXT)['mode']) == ['a', 'b', 'a']
    with pytest.raises(ValueError, match='3 parts'):
        field_comments('float64 x\n---\nbool y')
    with pytest.raises(ValueError, match='part must be'):
        field_comments(TEXT, 'request')


@pytest.fixture(scope='module')
def goal_comments():
    return field_comments(installed_action_text('helio_msgs', 'PaintPattern'))


def test_every_goal_option_has_its_meaning_and_numbers_their_unit(goal_comments):
    for name, kind, _ in goal_options(PaintPattern.Goal):
        comment = goal_comments.get(name, '')
        assert len(comment) > 10, f'PaintPattern goal field {name} has no comment'
        if kind in ('float', 'int', 'signed', 'points'):
            assert '[' in comment and ']' in comment, f'{name}: no unit in {comment!r}'


@pytest.mark.parametrize('field, choices', [('feature_mode', FEATURE_MODES),
                                            ('ordering', ORDERINGS),
                                            ('cooling', COOLING_RULES)])
def test_the_choices_a_comment_lists_are_the_codes(goal_comments, field, choices):
    assert set(listed_choices(goal_comments[field])) == set(choices), goal_comments[field]
