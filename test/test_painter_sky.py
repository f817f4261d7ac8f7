"""
The painter refuses a goal the sun cannot serve, naming ``helio sky`` (issue 30, item 7).

The painter node runs in this process on a simulated clock (``/clock`` published here at a
chosen instant), with no lens planner: a refused goal must end before any action is sent.
The lens planner's distances (``focus/distances``, which the painter checks reach at) are
published here as the lens planner publishes them, at the paper's 8.2 and 11.2 cm.
Its reasons come from ``helio_control.sky`` (tested in src/helio_control/test/test_sky.py);
here the node is held to the world's truths: the sun's elevation from pysolar at the site,
the sun ray of the simulated world's own ``Sun`` at a robot heading, and the rig model.
"""

import datetime
import math

from geometry_msgs.msg import Point
from helio_control.dot_layout import check_reach
from helio_control.painter_node import PainterNode
from helio_drivers.sim.sun import Sun
from helio_msgs.action import PaintPattern
from helio_msgs.msg import FocusDistances, SunEstimate
from helio_optics.ephemeris import Site, sun_position
from helio_optics.node_kit.conversions import stamp_from_seconds
from helio_optics.node_kit.in_process_graph import InProcessGraph, TRANSIENT_LOCAL_QOS
from helio_optics.rig_kinematics import Rig
import numpy as np
from pysolar import solar
import pytest
from rosgraph_msgs.msg import Clock

SITE = Site(48.137, 11.575, 520.0)      # the simulated world's site (sim_world.yaml)
UTC = datetime.timezone.utc
POINTS = [(0.05, 0.05), (0.05, 0.06)]   # the canvas corner nearest the arm's base


def site_file(tmp_path):
    """Write SITE as a site file; return its path."""
    path = tmp_path / 'site.yaml'
    path.write_text('/**:\n  ros__parameters:\n    site:\n'
                    f'      latitude_deg: {SITE.latitude_deg}\n'
                    f'      longitude_deg: {SITE.longitude_deg}\n'
                    f'      elevation: {SITE.elevation}\n')
    return str(path)


class PainterAt:
    """A painter node whose clock stands at one instant, and a client for its goals."""

    def __init__(self, graph, tmp_path, when):
        """Start the painter on `graph` with /clock held at `when` (UTC)."""
        self.graph = graph
        self.clock = graph.helper.create_publisher(Clock, '/clock', 10)
        stamp = stamp_from_seconds(when.timestamp())
        graph.helper.create_timer(0.02, lambda: self.clock.publish(Clock(clock=stamp)))
        self.estimates = graph.helper.create_publisher(SunEstimate, 'sun/estimate',
                                                       TRANSIENT_LOCAL_QOS)
        self.distances = graph.helper.create_publisher(FocusDistances, 'focus/distances',
                                                       TRANSIENT_LOCAL_QOS)
        self.distances.publish(FocusDistances(heating_distance=0.082, retreat_distance=0.112))
        self.node = graph.add(PainterNode(**graph.node_options(
            use_sim_time=True, site_file=site_file(tmp_path), calibrate_world='never',
            runs_dir=str(tmp_path / 'runs'))))
        self.client = graph.action_client(PaintPattern, 'paint')

    def publish_estimate(self, ray, when):
        """Publish a converged, precise sun estimate of `ray` (robot frame) at `when`."""
        message = SunEstimate(converged=True, covariance=[1e-8, 0.0, 0.0, 1e-8])
        message.header.stamp = stamp_from_seconds(when.timestamp())
        message.header.frame_id = 'robot'
        message.direction.x, message.direction.y, message.direction.z = map(float, ray)
        self.estimates.publish(message)
        self.graph.wait_until(lambda: self.node.sun is not None, 10.0,
                              'the painter to take the estimate')

    def paint(self, points):
        """Send a goal of world `points`; return its result."""
        goal = PaintPattern.Goal(points=[Point(x=x, y=y, z=0.0) for x, y in points])
        return self.graph.run_goal(self.client, goal, timeout=30.0).result


@pytest.fixture
def graph():
    with InProcessGraph('painter_sky_test') as graph:
        yield graph


def test_without_an_estimate_a_sun_too_low_for_the_sweep_is_refused(graph, tmp_path):
    night = datetime.datetime(2026, 6, 21, 1, 0, tzinfo=UTC)
    painter = PainterAt(graph, tmp_path, night)
    result = painter.paint(POINTS)
    assert not result.success
    assert result.message.startswith('refused: the sun cannot serve a painting now')
    assert 'helio sky' in result.message
    # the next sample, 10 minutes apart, at which pysolar puts the sun 30 deg up
    later = next(night + k * datetime.timedelta(minutes=10) for k in range(1, 200)
                 if solar.get_altitude(SITE.latitude_deg, SITE.longitude_deg,
                                       night + k * datetime.timedelta(minutes=10),
                                       elevation=SITE.elevation) >= 30.0)
    assert f'next at {later:%H:%M} UTC' in result.message
    assert result.dots_burnt == 0 and result.dots_planned == 0


def test_a_canvas_out_of_reach_of_the_estimated_sun_is_refused_naming_the_heading(graph,
                                                                                  tmp_path):
    noon = datetime.datetime(2026, 6, 21, 12, 0, tzinfo=UTC)
    painter = PainterAt(graph, tmp_path, noon)
    rig = Rig()
    ray = Sun(SITE, math.radians(30.0)).ray_robot(noon)     # a robot heading of 30 deg
    # the rig model (Eqs 14-15) reaches neither point at this sun
    assert not check_reach(np.array(POINTS), rig, ray, 0.082, 0.03).reachable.any()
    assert math.degrees(sun_position(SITE, noon).elevation) > 60.0
    painter.publish_estimate(ray, noon)
    result = painter.paint(POINTS)
    assert not result.success
    assert result.message.startswith('refused: the sun cannot serve this canvas now')
    assert 'helio sky --heading 30"' in result.message
    assert 'within reach next at ' in result.message
