"""
Benchmarks of pictures-to-dots: ``python -m helio_control.bench [--json PATH] [--quick]``.

Prints the figures and writes them as flat JSON (units in the key names):

- planning time per feature mode for a 1000 x 1000 picture (the sample portrait enlarged);
- ordering time and tour (arm seconds, metres) per method for 1,000 and 5,000 dots (random
  cells of an 80 x 80 grid of 1 mm dots on the 8 cm canvas), against fast_tsp given a long
  budget; the time-matrix build; a Euclidean-metre proxy tour priced in arm seconds;
- ``plan_picture`` end to end for a picture that gives about 5,000 dots (target: < 2 s with
  the default solver settings);
- the quality figures, dot counts and time estimates of the sample pictures.

Numeric libraries are pinned to one thread (threadpoolctl, cv2.setNumThreads) and fast_tsp
runs on one thread, so figures compare within one run on the shared 2-core machine.
"""

import argparse
import time

import cv2
from helio_control.cycle_model import load_cycle_config
from helio_control.dot_layout import check_reach
from helio_control.path_ordering import default_budget, fast_tsp_order, order_dots, ORDERINGS
from helio_control.path_ordering import TravelMetric
from helio_control.plan import default_rig, load_plan_options, plan_picture
from helio_control.samples import portrait_picture, SAMPLE_NAMES
from helio_optics.bench_report import add_json_option, median_call_ms, report
import numpy as np


def _timed(call):
    start = time.perf_counter()
    result = call()
    return result, time.perf_counter() - start


def planning_figures(figures, repeats):
    """Planning time per mode for the 1000 x 1000 portrait."""
    picture = cv2.resize(portrait_picture(512), (1000, 1000), interpolation=cv2.INTER_CUBIC)
    for mode in ('edges', 'centerline', 'threshold', 'tones'):
        options = load_plan_options(feature_mode=mode)
        plan = plan_picture(picture, options)
        figures[f'plan_1000x1000_{mode}_ms_median'] = median_call_ms(
            lambda: plan_picture(picture, options), repeats)
        figures[f'plan_1000x1000_{mode}_dots'] = len(plan)


def ordering_figures(figures, counts, long_budget_s):
    """Ordering time and tour per method, random cells of an 80 x 80 grid at 1 mm."""
    options = load_plan_options()
    rig = default_rig()[0]
    model_limits = load_cycle_config()[1]
    rng = np.random.default_rng(11)
    u, v = np.meshgrid(np.arange(80), np.arange(80))
    cells = np.column_stack([u.ravel(), v.ravel()])
    for count in counts:
        chosen = cells[rng.choice(len(cells), count, replace=False)]
        points = options.offset_x + 0.001 * chosen
        reach, seconds = _timed(lambda: check_reach(points, rig, options.nominal_sun_ray(),
                                                    options.d_lp, options.retreat))
        figures[f'reach_{count}_dots_s'] = seconds
        metric = TravelMetric(reach.joints_retreat, model_limits, points)
        _, seconds = _timed(metric.matrix)
        figures[f'time_matrix_{count}_dots_s'] = seconds
        tours = {}
        for method in ORDERINGS:
            order, seconds = _timed(lambda: order_dots(metric, method, chosen))
            tours[method] = metric.path_time(order)
            figures[f'order_{count}_{method}_s'] = seconds
            figures[f'order_{count}_{method}_tour_arm_s'] = tours[method]
            figures[f'order_{count}_{method}_tour_m'] = metric.path_length(order)
        long_order = fast_tsp_order(metric.matrix(), long_budget_s, stop_when_converged=False)
        best = min(min(tours.values()), metric.path_time(long_order))
        figures[f'order_{count}_fast_tsp_long_{long_budget_s:g}s_tour_arm_s'] = \
            metric.path_time(long_order)
        figures[f'order_{count}_default_over_best_ratio'] = tours['fast_tsp'] / best
        figures[f'order_{count}_nearest_2opt_over_paper_ratio'] = \
            tours['nearest_2opt'] / tours['paper']
        figures[f'order_{count}_default_budget_s'] = default_budget(count)
        # A Euclidean proxy: the best tour in metres, priced in arm seconds.
        steps = points[:, None, :] - points[None, :, :]
        metres = np.hypot(steps[..., 0], steps[..., 1])
        proxy = fast_tsp_order(metres, default_budget(count))
        figures[f'order_{count}_metre_proxy_over_time_tour_ratio'] = \
            metric.path_time(proxy) / tours['fast_tsp']


def end_to_end_figures(figures, repeats):
    """plan_picture for about 5,000 dots: 1 mm dots, a darkened portrait in tones."""
    picture = cv2.resize(portrait_picture(512), (1000, 1000), interpolation=cv2.INTER_CUBIC)
    options = load_plan_options(feature_mode='tones', dot_radius=0.001, tone_gamma=0.25)
    plan = plan_picture(picture, options)
    figures['plan_and_order_tones_1mm_dots'] = len(plan)
    figures['plan_and_order_tones_1mm_s_median'] = median_call_ms(
        lambda: plan_picture(picture, options), repeats) / 1e3


def sample_figures(figures):
    """Quality, dots and time estimate of each sample picture in auto mode."""
    for name in SAMPLE_NAMES:
        plan = plan_picture(f'sample:{name}', load_plan_options())
        kind = plan.quality['kind']
        unit = 'mm' if kind == 'chamfer_mm' else ''
        label = 'chamfer' if kind == 'chamfer_mm' else 'ssim'
        figures[f'sample_{name}_{plan.mode}_{label}{"_" + unit if unit else ""}'] = \
            plan.quality['value']
        figures[f'sample_{name}_dots'] = len(plan)
        figures[f'sample_{name}_estimate_min'] = plan.time_estimate['total_s'] / 60.0
        figures[f'sample_{name}_travel_arm_s'] = plan.travel_s


def run(quick=False):
    """Run every benchmark on one thread; return the flat dict of figures."""
    from threadpoolctl import threadpool_limits

    cv2.setNumThreads(1)
    figures = {}
    with threadpool_limits(1):
        planning_figures(figures, 1 if quick else 3)
        ordering_figures(figures, (1000,) if quick else (1000, 5000), 1.0 if quick else 10.0)
        end_to_end_figures(figures, 1 if quick else 3)
        sample_figures(figures)
    return figures


def main(args=None):
    """Parse arguments, run, print and optionally write JSON."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    add_json_option(parser)
    parser.add_argument('--quick', action='store_true',
                        help='1,000 dots only, one repetition, short long-budget')
    options = parser.parse_args(args)
    return report(run(options.quick), options.json, machine=True)


if __name__ == '__main__':
    raise SystemExit(main())
