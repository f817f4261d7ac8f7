"""
What each field of an action means, read from the action's own definition (issue 32).

The comments of a ``.action`` file are where a field's unit and meaning are written once;
``helio paint --help`` shows them from there (``field_comments``), so a new goal field
brings its help with it. No rclpy: the installed definition is found with ament_index.
"""

import os
import re

PARTS = ('goal', 'result', 'feedback')
_FIELD = re.compile(r'^\s*([A-Za-z][\w/]*(?:\[\d*\])?)\s+([a-z][a-z0-9_]*)\s*(?:#\s?(.*))?$')
_CONTINUATION = re.compile(r'^\s+#\s?(.*)$')


def field_comments(text, part='goal'):
    """
    Return {field name: its comment} of one part of an action definition's `text`.

    A field's comment is the text after ``#`` on its line, joined with the comment-only lines
    indented under it (a comment that goes on); fields without one map to ''. Constants
    (``TYPE NAME=VALUE``) are not fields.
    """
    if part not in PARTS:
        raise ValueError(f'part must be one of {PARTS}, not {part!r}')
    sections = re.split(r'^---\s*$', text, flags=re.MULTILINE)
    if len(sections) != 3:
        raise ValueError(f'an action definition has 3 parts split by ---, this has '
                         f'{len(sections)}')
    comments, last = {}, None
    for line in sections[PARTS.index(part)].splitlines():
        follows = _CONTINUATION.match(line)
        if follows and last is not None:
            comments[last] = f'{comments[last]} {follows.group(1).strip()}'.strip()
            continue
        match = _FIELD.match(line)
        if match and '=' not in line.split('#', 1)[0]:
            last = match.group(2)
            comments[last] = (match.group(3) or '').strip()
        else:
            last = None
    return comments


def installed_action_text(package, action):
    """Return the text of `package`'s installed ``action/<action>.action``."""
    from ament_index_python.packages import get_package_share_directory
    path = os.path.join(get_package_share_directory(package), 'action', f'{action}.action')
    with open(path) as stream:
        return stream.read()


def listed_choices(comment):
    """Return the quoted words of a comment, in order (the choices it lists), '' left out."""
    return [word for word in re.findall(r'"([^"]*)"', comment) if word]
