"""
The picture options, each described once: what it is, its unit, what else to know (issue 32).

``plan.PlanOptions`` holds the options' names, types and defaults (config/picture.yaml
writes the same defaults); this table says what each one means. The ``--help`` lines are
generated from it and the other places that describe an option are checked against it
(``test/test_picture_options.py``):

- ``helio preview`` (``python -m helio_control.preview``): one option per picture option
  (``add_option_arguments``), its help ``help_line(name)``;
- ``helio sky``: its canvas options, the same way;
- ``helio paint``: one option per PaintPattern goal field, whose help is the field's comment
  in the action (``action_docs``); a goal field that is a picture option
  (``plan.GOAL_FIELDS``) must begin its comment with this table's ``OptionDoc.head()``;
- config/picture.yaml: each number's comment gives this table's unit.

Standard library only: the ``helio`` command builds its parser from it at every start.
"""

import argparse
from dataclasses import dataclass


@dataclass(frozen=True)
class OptionDoc:
    """What one picture option is: quantity (the paper's symbol), unit, and a note."""

    quantity: str       # what it is, with the paper's symbol where it has one
    unit: str           # shown in brackets; '' for a word (choices) or a switch
    note: str           # what it does, what 0 means, the paper's value

    def head(self):
        """Return the quantity with its unit: 'canvas side l_w [m]'."""
        return f'{self.quantity} [{self.unit}]' if self.unit else self.quantity

    def line(self):
        """Return the option's help line: the head and the note."""
        return f'{self.head()} - {self.note}'

    def metavar(self, kind):
        """Return the placeholder of a value of this option (`kind`: its type)."""
        return unit_metavar(self.unit, kind)


def unit_metavar(unit, kind):
    """Return the placeholder of a value in `unit` of type `kind`: M, DEG, S, else N or X."""
    return {'m': 'M', 'deg': 'DEG', 's': 'S'}.get(unit, 'N' if kind is int else 'X')


OPTIONS = {
    'canvas_size': OptionDoc('canvas side l_w', 'm', 'the square the picture is painted into '
                             '(paper: < 10 cm)'),
    'dot_radius': OptionDoc(
        'dot pitch r_p', 'm', 'the spacing of the dot grid (paper 0.2 cm); with a dot-size '
        'calibration (dots.yaml, "helio calibrate dots") the painter also burns each dot this '
        'wide unless n_p_target is given; without one a dot is as wide as n_p_target makes '
        'it'),
    'offset_x': OptionDoc('canvas offset d_x', 'm', 'the canvas corner from the marker centre '
                          'along world x (paper 5 cm)'),
    'offset_y': OptionDoc('canvas offset d_y', 'm', 'the canvas corner from the marker centre '
                          'along world y (paper 5 cm)'),
    'n_p_target': OptionDoc('N_p target per dot', 'pixels', 'heating a dot stops when this '
                            'many thermal pixels are above the pyrolysis threshold (paper 30)'),
    'feature_mode': OptionDoc('feature extraction', '', 'how the picture becomes dots '
                              '(Sec. IV-C); auto: chosen from the picture'),
    'ordering': OptionDoc('burn order', '', 'fast_tsp: the shortest tour; paper: grouped by '
                          'u, ordered by v; nearest: greedy; nearest_2opt: greedy, then 2-opt'),
    'v_axis': OptionDoc('picture v axis', '', "flip: the picture's top at the largest world y "
                        '(reads right from above); paper: y = v r_p + d_y'),
    'max_canvas_size': OptionDoc('largest canvas accepted', 'm', 'the default rig reaches '
                                 '10 cm (helio_optics README)'),
    'oversample': OptionDoc('working-image oversampling', 'pixels per dot pitch',
                            'resolution of the feature extraction'),
    'canny_low': OptionDoc('Canny lower threshold', 'grey level 0..255',
                           'edges mode: hysteresis'),
    'canny_high': OptionDoc('Canny upper threshold', 'grey level 0..255',
                            'edges mode: hysteresis'),
    'threshold_block_nodes': OptionDoc('adaptive threshold block', 'dot pitches',
                                       'threshold mode: the neighbourhood of the local mean'),
    'threshold_offset': OptionDoc('adaptive threshold offset', 'grey 0..1', 'threshold mode: '
                                  'a cell is dark when darker than the local mean by this'),
    'tone_kernel': OptionDoc('error-diffusion kernel', '', 'tones mode'),
    'tone_gamma': OptionDoc('darkness exponent', '-', 'tones mode: applied before error '
                            'diffusion'),
    'tone_dot_size': OptionDoc('dot size by tone', '', "tones mode: also scale each dot's N_p "
                               "target with its cell's darkness, from n_p_min to n_p_target "
                               '(Fig. 8d)'),
    'n_p_min': OptionDoc('smallest N_p target', 'pixels', 'the lightest tone when '
                         'tone_dot_size is on'),
    'd_lp': OptionDoc('heating distance d_lp', 'm', 'lens plane to the wood while heating; the '
                      'plan checks reach with it (paper 8.2 cm)'),
    'retreat': OptionDoc('retreat offset delta d_lp', 'm', 'the lens this far above the '
                         'heating distance between dots (paper 3 cm)'),
    'solver_budget_s': OptionDoc('fast_tsp time budget', 's', '0: 0.1 ms per dot, within '
                                 '0.05..0.5 s'),
    'min_separation': OptionDoc('close-dot distance', 'm', 'successive dots closer than this '
                                "cost the cycle model's cooling wait (0: off; the painter's "
                                'window rule sets it)'),
    'cooling_wait': OptionDoc('cooling wait in the estimate', '', 'the time estimate waits the '
                              "cycle model's cooling_s after each dot (off: the window rule)"),
    'sun_elevation_deg': OptionDoc('nominal sun elevation', 'deg', 'the sun the plan assumes '
                                   'when no estimate is given'),
    'sun_azimuth_deg': OptionDoc('nominal sun azimuth', 'deg', 'towards the sun, '
                                 'counter-clockwise from robot x'),
}


# the options that place the canvas and the lens over it: what ``helio sky`` checks the sun for
CANVAS_OPTIONS = ('canvas_size', 'offset_x', 'offset_y', 'd_lp', 'retreat')


def help_line(name):
    """Return the ``--help`` line of the picture option `name` (KeyError: no such option)."""
    return OPTIONS[name].line()


def option_flag(name):
    """Return the command-line spelling of an option: ``--canvas-size`` for canvas_size."""
    return '--' + name.replace('_', '-')


def add_option_arguments(parser, names, types, choices=None):
    """
    Add one option per picture option of `names` to `parser` (a parser or a group).

    `types` maps a name to its type: ``bool`` becomes ``--x/--no-x``, any other type (or
    converter) reads the value; a name in `choices` ({name: allowed}) takes one of those.
    Each option's destination is its name, its default None (not given), its help
    ``help_line(name)``.
    """
    for name in names:
        text = help_line(name).replace('%', '%%')
        if types[name] is bool:
            parser.add_argument(option_flag(name), dest=name, default=None, help=text,
                                action=argparse.BooleanOptionalAction)
        elif choices and name in choices:
            parser.add_argument(option_flag(name), dest=name, choices=tuple(choices[name]),
                                help=text)
        else:
            parser.add_argument(option_flag(name), dest=name, type=types[name], help=text,
                                metavar=OPTIONS[name].metavar(types[name]))
