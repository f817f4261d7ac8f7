"""
Preview a painting plan: ``python -m helio_control.preview PICTURE --out DIR [options]``.

Writes ``DIR/preview.png`` (a top view of the panel: the ArUco marker at the world origin,
the canvas, the dots in burn order with the path between them, rejected dots as red
crosses, a scale bar and the figures; the input picture beside it) and ``DIR/plan.json``
(``Plan.to_json``: ordered dots in world metres, per-dot N_p targets, travel, time
estimate, quality, mode and every parameter used).

PICTURE is a file OpenCV reads or ``sample:text``, ``sample:logo``, ``sample:portrait``.
The options are the picture options (``plan.PlanOptions``, config/picture.yaml), one
each, generated with their unit and meaning from ``picture_options.OPTIONS``; an option
not given keeps the options file's value.

Exit status: 0 done, 1 the picture or the plan failed (one line on stderr), 2 bad
options. It becomes a sub-command of the operator command line later.
"""

import argparse
from dataclasses import fields
import math
import os
import sys

import cv2
from helio_control.picture_input import load_picture, PictureError
from helio_control.picture_options import add_option_arguments
from helio_control.plan import load_plan_options, OPTION_CHOICES, plan_picture, PlanError
from helio_control.plan import PlanOptions, PlanOptionsError
import numpy as np

MARKER_SIDE = 0.04           # ArUco marker side drawn at the world origin [m]
WOOD = (176, 208, 228)       # BGR of bare wood
CHAR = (30, 40, 60)          # BGR of a charred dot


def _world_to_pixel(scale, x_min, y_max):
    def convert(x, y):
        return (int(round((x - x_min) * scale)), int(round((y_max - y) * scale)))
    return convert


def render_preview(plan, picture=None, target_px=1000):
    """
    Return the preview image (BGR uint8): top view of marker, canvas, dots and path.

    World x to the right, world y up (as seen from above the panel); `picture` (a Picture)
    is drawn to the right at the canvas' height.
    """
    p = plan.parameters
    size, pitch = p['canvas_size'], p['dot_radius']
    x0, y0 = p['offset_x'], p['offset_y']
    margin = 0.012
    x_min = min(-MARKER_SIDE / 2, x0) - margin
    x_max = max(MARKER_SIDE / 2, x0 + size) + margin
    y_min = min(-MARKER_SIDE / 2, y0) - margin
    y_max = max(MARKER_SIDE / 2, y0 + size) + margin + 0.02   # room for the title
    scale = target_px / max(x_max - x_min, y_max - y_min)
    width = int(math.ceil((x_max - x_min) * scale))
    height = int(math.ceil((y_max - y_min) * scale))
    image = np.full((height, width, 3), WOOD, np.uint8)
    to_px = _world_to_pixel(scale, x_min, y_max)
    _draw_marker(image, to_px, scale)
    _draw_axes(image, to_px, scale)
    cv2.rectangle(image, to_px(x0 - pitch / 2, y0 + size - pitch / 2),
                  to_px(x0 + size - pitch / 2, y0 - pitch / 2), (90, 120, 140), 1, cv2.LINE_AA)
    dots = np.asarray(plan.dots).reshape(-1, 2)
    count = len(dots)
    for index in range(count - 1):
        shade = index / max(1, count - 2)
        colour = (int(255 * (1 - shade)), 60, int(255 * shade))   # blue at start -> red
        cv2.line(image, to_px(*dots[index]), to_px(*dots[index + 1]), colour, 1, cv2.LINE_AA)
    target = float(p.get('n_p_target', 30))
    for (x, y), n_p in zip(dots, plan.n_p_targets):
        radius = 0.5 * pitch * math.sqrt(max(n_p, 1) / target) * scale
        cv2.circle(image, to_px(x, y), max(1, int(round(radius))), CHAR, -1, cv2.LINE_AA)
    if count:
        cv2.circle(image, to_px(*dots[0]), int(pitch * scale), (255, 90, 0), 2, cv2.LINE_AA)
        _text(image, 'start', np.add(to_px(*dots[0]), (int(pitch * scale) + 3, 4)), 0.45,
              (255, 90, 0))
    for rejection in plan.rejected:
        cx, cy = to_px(rejection['x_m'], rejection['y_m'])
        arm = max(2, int(0.4 * pitch * scale))
        cv2.line(image, (cx - arm, cy - arm), (cx + arm, cy + arm), (0, 0, 230), 2)
        cv2.line(image, (cx - arm, cy + arm), (cx + arm, cy - arm), (0, 0, 230), 2)
    _draw_scale_bar(image, scale)
    estimate = plan.time_estimate
    quality = plan.quality
    quality_text = (f'chamfer {quality["value"]:.2f} mm' if quality.get('kind') == 'chamfer_mm'
                    else f'SSIM {quality.get("value", float("nan")):.3f}')
    lines = [f'{p.get("picture", "")}: mode {plan.mode}, ordering {plan.ordering}, '
             f'{count} dots, {len(plan.rejected)} rejected',
             f'time ~{estimate.get("total_s", 0) / 60:.0f} min '
             f'({estimate.get("total_low_s", 0) / 60:.0f}-'
             f'{estimate.get("total_high_s", 0) / 60:.0f}), travel {plan.travel_m:.2f} m / '
             f'{plan.travel_s:.0f} s, {quality_text}']
    for row, line in enumerate(lines):
        _text(image, line, (10, 22 + 22 * row), 0.55, (20, 20, 20))
    if picture is not None:
        image = np.hstack([image, _picture_panel(picture, height)])
    return image


def _text(image, text, origin, size, colour):
    origin = (int(origin[0]), int(origin[1]))
    cv2.putText(image, text, origin, cv2.FONT_HERSHEY_SIMPLEX, size, colour, 1, cv2.LINE_AA)


def _draw_marker(image, to_px, scale):
    side = max(8, int(round(MARKER_SIDE * scale)))
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    marker = cv2.aruco.generateImageMarker(dictionary, 0, side)
    left, top = to_px(-MARKER_SIDE / 2, MARKER_SIDE / 2)
    region = image[top:top + side, left:left + side]
    region[:] = cv2.cvtColor(marker[:region.shape[0], :region.shape[1]], cv2.COLOR_GRAY2BGR)


def _draw_axes(image, to_px, scale):
    origin = to_px(0.0, 0.0)
    for (dx, dy), colour, name in (((0.03, 0.0), (0, 0, 220), 'x'),
                                   ((0.0, 0.03), (0, 160, 0), 'y')):
        tip = to_px(dx, dy)
        cv2.arrowedLine(image, origin, tip, colour, 2, cv2.LINE_AA, tipLength=0.15)
        _text(image, name, (tip[0] + 4, tip[1] - 4), 0.6, colour)


def _draw_scale_bar(image, scale):
    length = int(round(0.01 * scale))
    height = image.shape[0]
    start = (12, height - 14)
    cv2.line(image, start, (start[0] + length, start[1]), (20, 20, 20), 3)
    _text(image, '10 mm', (start[0], start[1] - 8), 0.5, (20, 20, 20))


def _picture_panel(picture, height):
    grey = np.clip(picture.grey * 255.0 + 0.5, 0, 255).astype(np.uint8)
    box = 0.45 * height
    zoom = min(box / grey.shape[0], box / grey.shape[1])
    width = max(1, int(round(grey.shape[1] * zoom)))
    shown = cv2.resize(grey, (width, max(1, int(round(grey.shape[0] * zoom)))),
                       interpolation=cv2.INTER_AREA)
    panel = np.full((height, width + 20, 3), 255, np.uint8)
    panel[30:30 + shown.shape[0], 10:10 + width] = cv2.cvtColor(shown, cv2.COLOR_GRAY2BGR)
    _text(panel, 'input picture', (10, 20), 0.55, (20, 20, 20))
    return panel


def write_preview(plan, picture, directory):
    """Write preview.png and plan.json into `directory`; return their paths."""
    os.makedirs(directory, exist_ok=True)
    png = os.path.join(directory, 'preview.png')
    if not cv2.imwrite(png, render_preview(plan, picture)):
        raise OSError(f'cannot write {png}')
    path = os.path.join(directory, 'plan.json')
    with open(path, 'w') as stream:
        stream.write(plan.to_json() + '\n')
    return png, path


OPTION_NAMES = tuple(f.name for f in fields(PlanOptions))     # every one is an option here


def build_parser(prog='python -m helio_control.preview'):
    """Return the argparse parser of the preview command (`prog`: how it was called)."""
    parser = argparse.ArgumentParser(
        prog=prog,
        description='Plan the dots of a picture (paper Sec. IV-C, Eq 17) and write '
                    'preview.png and plan.json.')
    parser.add_argument('picture', help='picture file (PNG, JPEG, BMP, TIFF, ...) or '
                                        'sample:text, sample:logo, sample:portrait')
    parser.add_argument('--out', default='.', help='output directory (default: .)')
    parser.add_argument('--config', help='picture options file (default: config/picture.yaml)')
    add_option_arguments(
        parser.add_argument_group("picture options (not given: the options file's value)"),
        OPTION_NAMES, {f.name: type(f.default) for f in fields(PlanOptions)}, OPTION_CHOICES)
    return parser


def main(args=None, prog='python -m helio_control.preview'):
    """Run the preview command; return the exit status (0, 1 or 2)."""
    parser = build_parser(prog)
    arguments = parser.parse_args(args)
    overrides = {name: getattr(arguments, name) for name in OPTION_NAMES}
    try:
        options = load_plan_options(arguments.config, **overrides).validate()
    except PlanOptionsError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    except (OSError, ValueError) as error:
        print(f'error: options file: {error}', file=sys.stderr)
        return 2
    try:
        picture = load_picture(arguments.picture)
        plan = plan_picture(picture, options)
        png, path = write_preview(plan, picture, arguments.out)
    except (PictureError, PlanError) as error:
        print(f'error: {error}', file=sys.stderr)
        return 1
    except OSError as error:
        print(f'error: {error}', file=sys.stderr)
        return 1
    for warning in plan.warnings:
        print(f'warning: {warning}', file=sys.stderr)
    estimate = plan.time_estimate
    print(f'{len(plan)} dots ({plan.mode}, {plan.ordering}), {len(plan.rejected)} rejected; '
          f'time ~{estimate["total_s"] / 60:.1f} min; quality {plan.quality.get("kind")} '
          f'{plan.quality.get("value")}; wrote {png} and {path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
