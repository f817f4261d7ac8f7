"""
The ``helio`` command: run the graph, paint, record, replay, report.

::

    helio sim [--real-time-factor X] [--out DIR] [--nodes ...] [--set NODE.PARAM=VALUE] [--view]
    helio rig --dobot-port PORT|auto --servo-port PORT [--rgb-camera PKG/EXE] ... [--view]
    helio preview PICTURE --out DIR [options]       (no graph needed)
    helio paint PICTURE [goal options] [--out DIR] [--sim [--set NODE.PARAM=VALUE]] [--view]
    helio record --out DIR [--camera-decimation N] [--sim-time] | --recover BAG
    helio replay BAG [--rate R] [--delay S] [--exclude TOPIC ...] [--view]
    helio view [--port P] [--namespace NS]           (the live Foxglove view of a graph)
    helio report RUN_DIR
    helio print marker|board --out FILE.png|pdf [--side M] ...   (a sheet to print at 1:1)
    helio udev [--install]                           (the serial devices' udev rule)
    helio calibrations [--dir DIR] [--rig FILE]      (what is saved, and for which rig)
    helio calibrate rig|world [--poses N] [--no-apply]   (run one on the running graph)
    helio calibrate camera [--board-centre X Y] [--board-square M] ...   (the RGB camera)
    helio calibrate dots [--n-p-targets N ...] [--row X Y] ...   (N_p target -> dot size)
    helio doctor [--namespace NS] [--window S] ...   (the rig's checklist, a fix for each)
    helio stop [--namespace NS]                      (the emergency stop)
    helio sky [--date D] [--heading DEG] [--site FILE] [options]   (when the sun serves)
    helio reset [--namespace NS]                     (release it)

Every sub-command has ``--help``. Exit status: 0 done, 1 failed (one line on stderr, no
traceback), 2 bad usage, 130 interrupted (Ctrl-C). The options of ``paint`` are generated
from the fields of the PaintPattern goal (``goal_options``), so a field added to the action
is an option at once.
"""

import argparse
import datetime
import math
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130
# USB ids of the Dobot Magician's USB-serial adapter: Silicon Labs CP210x on the original
# board, WCH CH340 on later ones. Both are common chips: a second adapter of the same kind
# makes `--dobot-port auto` refuse to guess.
DOBOT_USB_IDS = ((0x10C4, 0xEA60), (0x1A86, 0x7523))
GOAL_SOURCE_FIELDS = ('image_path', 'image')     # set from PICTURE, not options


class CommandError(Exception):
    """A failure reported as one line and exit status 1."""


# ---------------------------------------------------------------------------- the graph's actions
START_THE_GRAPH = 'start the graph ("helio rig" or "helio sim")'


def ros_domain():
    """Return ROS_DOMAIN_ID as a message names it (unset: '0 (unset)')."""
    return os.environ.get('ROS_DOMAIN_ID', '') or '0 (unset)'


def no_server_error(graph, who, name, timeout, advice=START_THE_GRAPH):
    """Return the CommandError of an action `name` nobody served: who, where, what to do."""
    return CommandError(f'no {who} answers on {graph.helper.resolve_topic_name(name)} in '
                        f'ROS_DOMAIN_ID {ros_domain()} within {timeout:g} s: {advice}')


def connect_action(graph, action_type, name, timeout, who, advice=START_THE_GRAPH):
    """
    Return an ActionClient of the action `name` once its server answers.

    `graph` is the command's ``ClientGraph``; no server within `timeout` s raises the
    CommandError of ``no_server_error`` (`who`: the node expected to serve it).
    """
    from rclpy.action import ActionClient
    client = ActionClient(graph.helper, action_type, name)
    if not client.wait_for_server(timeout_sec=timeout):
        raise no_server_error(graph, who, name, timeout, advice)
    return client


# ---------------------------------------------------------------------------- paint options
def goal_options(goal_type):
    """
    Return [(field, kind, option name)] for the goal's fields that the command line sets.

    kind is 'float', 'int' (unsigned: >= 0), 'signed', 'str', 'bool' or 'points' (a
    sequence of geometry_msgs/Point given as X,Y pairs). Fields of other types (and the
    picture's own fields) are left out.
    """
    kinds = {'double': 'float', 'float': 'float', 'string': 'str', 'boolean': 'bool',
             'sequence<geometry_msgs/Point>': 'points'}
    for bits in ('8', '16', '32', '64'):
        kinds[f'uint{bits}'] = 'int'
        kinds[f'int{bits}'] = 'signed'
    options = []
    for name, idl_type in goal_type.get_fields_and_field_types().items():
        if name in GOAL_SOURCE_FIELDS or idl_type not in kinds:
            continue
        options.append((name, kinds[idl_type], '--' + name.replace('_', '-')))
    return options


def _number(name, convert, accept, rule):
    """
    Return an argparse type called `name`: `convert` the text, refuse what `accept` does not.

    A text `convert` cannot read is "invalid <name> value"; a number it refuses, "must be
    <rule>, not <text>".
    """
    def parse(text):
        value = convert(text)
        if not accept(value):
            raise argparse.ArgumentTypeError(f'must be {rule}, not {text}')
        return value
    parse.__name__ = name
    return parse


_non_negative_int = _number('_non_negative_int', int, lambda value: value >= 0, '>= 0')
_positive_int = _number('_positive_int', int, lambda value: value >= 1, '>= 1')
_finite_float = _number('_finite_float', float, math.isfinite, 'a finite number')
_positive_float = _number('_positive_float', float,
                          lambda value: math.isfinite(value) and value > 0.0, '> 0')


def _point(text):
    try:
        x, y = (float(v) for v in text.split(','))
    except ValueError:
        raise argparse.ArgumentTypeError(f'a point is X,Y in metres, not {text!r}') from None
    return x, y


def add_goal_options(parser, goal_type, comments=None):
    """
    Add one option per goal field (see `goal_options`).

    Each option's help is its field's comment in the action's definition (`comments`:
    {field: comment}, by default read from the installed PaintPattern.action), where its unit
    and meaning are written once.
    """
    from helio_control.picture_options import unit_metavar
    if comments is None:
        from helio_control import action_docs
        comments = action_docs.field_comments(
            action_docs.installed_action_text('helio_msgs', 'PaintPattern'))
    group = parser.add_argument_group('PaintPattern goal fields (unset: the painter default)')
    for name, kind, option in goal_options(goal_type):
        meaning = comments.get(name, '').replace('%', '%%')
        text = f'{name}: {meaning}' if meaning else f'goal field {name}'
        unit = re.search(r'\[([^\]]+)\]', meaning)
        if kind == 'bool':
            group.add_argument(option, dest=f'goal_{name}', action='store_true', default=None,
                               help=text)
        elif kind == 'points':
            group.add_argument(option, dest=f'goal_{name}', nargs='+', type=_point,
                               metavar='X,Y', help=text)
        else:
            convert = {'float': _finite_float, 'int': _non_negative_int, 'signed': int,
                       'str': str}[kind]
            metavar = 'TEXT' if kind == 'str' else unit_metavar(
                unit.group(1) if unit else '', float if kind == 'float' else int)
            group.add_argument(option, dest=f'goal_{name}', type=convert, help=text,
                               metavar=metavar)


def build_goal(goal_type, arguments, picture):
    """Return the goal: `picture` as image_path, every option that was given."""
    goal = goal_type()
    if picture:
        goal.image_path = picture
    for name, kind, _ in goal_options(goal_type):
        value = getattr(arguments, f'goal_{name}', None)
        if value is None:
            continue
        if kind == 'points':
            from geometry_msgs.msg import Point
            value = [Point(x=x, y=y, z=0.0) for x, y in value]
        setattr(goal, name, value)
    return goal


def resolve_picture(picture):
    """Return the picture as the painter must read it: an absolute path or sample:NAME."""
    if picture.startswith('sample:'):
        from helio_control.samples import SAMPLE_NAMES
        name = picture.split(':', 1)[1]
        if name not in SAMPLE_NAMES:
            raise CommandError(f'no sample picture {name!r} (samples: '
                               f'{", ".join(SAMPLE_NAMES)})')
        return picture
    path = os.path.abspath(os.path.expanduser(picture))
    if not os.path.isfile(path):
        raise CommandError(f'picture not found: {picture}')
    return path


# ---------------------------------------------------------------------------- ports
def find_dobot_port(ports=None):
    """Return the serial port of the one connected Dobot (by its adapter's USB ids)."""
    if ports is None:
        from serial.tools import list_ports
        ports = list_ports.comports()
    found = [p for p in ports if (p.vid, p.pid) in DOBOT_USB_IDS]
    known = ', '.join(f'{vid:04x}:{pid:04x}' for vid, pid in DOBOT_USB_IDS)
    if not found:
        listed = ', '.join(f'{p.device} ({p.vid or 0:04x}:{p.pid or 0:04x})' for p in ports)
        raise CommandError(f'no Dobot found: no serial port with USB ids {known}; ports: '
                           f'{listed or "none"} (is it plugged in and powered? give '
                           '--dobot-port)')
    if len(found) > 1:
        raise CommandError('several serial ports could be the Dobot (' +
                           ', '.join(p.device for p in found) + '): give --dobot-port')
    return found[0].device


# ---------------------------------------------------------------------------- graph commands
def _overrides(settings):
    overrides = {}
    for setting in settings or ():
        name, equals, text = setting.partition('=')
        node, dot, parameter = name.partition('.')
        if not equals or not dot or not node or not parameter:
            raise CommandError(f'--set takes NODE.PARAMETER=VALUE, not {setting!r}')
        import yaml
        overrides.setdefault(node, {})[parameter] = yaml.safe_load(text)
    return overrides


def _announce(log_dir):
    def started(group):
        print(f'[helio] running {len(group.processes)} nodes (logs in {log_dir}); Ctrl-C '
              'stops them', file=sys.stderr, flush=True)
        for process in group.processes:
            print(f'[helio]   {process.label} pid {process.pid}', file=sys.stderr, flush=True)
    return started


def command_sim(arguments):
    """Start the simulated graph and supervise it."""
    from helio_control.bringup import simulated_graph
    overrides = _overrides(arguments.set)
    world = overrides.setdefault('sim_world', {})
    world.setdefault('real_time_factor', arguments.real_time_factor)
    if arguments.out:
        world.setdefault('output_dir', os.path.abspath(arguments.out))
    port_dir = arguments.port_dir or tempfile.mkdtemp(prefix='helio_sim_ports_')
    return _supervise(arguments, 'sim', lambda: _with_view(
        arguments, simulated_graph(port_dir, arguments.nodes, overrides), sim_time=True))


def command_rig(arguments):
    """Start the hardware graph and supervise it."""
    from helio_control.bringup import CameraSpec, hardware_graph
    dobot_port = arguments.dobot_port
    if dobot_port == 'auto':
        dobot_port = find_dobot_port()
        print(f'[helio] Dobot found on {dobot_port}', file=sys.stderr)
    for port in (dobot_port, arguments.servo_port):
        if not os.path.exists(port):
            raise CommandError(f'serial port {port} does not exist (plugged in? see '
                               '"ls /dev/serial/by-id/"; --dobot-port auto finds a Dobot)')
    cameras = []
    for kind in ('rgb', 'thermal'):
        driver = getattr(arguments, f'{kind}_camera')
        if driver:
            parameters = _overrides([f'{kind}.{s}' for s in
                                     getattr(arguments, f'{kind}_camera_param') or ()])
            cameras.append(CameraSpec(kind, driver, parameters.get(kind, {})))
    return _supervise(arguments, 'rig', lambda: _with_view(arguments, hardware_graph(
        dobot_port, arguments.servo_port, cameras, arguments.nodes, _overrides(arguments.set)),
        sim_time=False))


def _with_view(arguments, specs, sim_time):
    """Return the graph's node specs, with the Foxglove view bridge when --view asks."""
    if not arguments.view:
        return specs
    from helio_control.bringup import NodeSpec
    print(f'[helio] Foxglove view: ws://127.0.0.1:{arguments.view_port} (README, "Watching '
          'a painting")', file=sys.stderr)
    return [*specs, NodeSpec('helio_control', 'view_bridge', 'view_bridge.yaml',
                             {'port': arguments.view_port}, sim_time=sim_time)]


def _view_process(arguments, log_dir, sim_time, plan_file=''):
    """Return the started view bridge process when --view asks, else None."""
    if not getattr(arguments, 'view', False):
        return None
    from helio_control.bringup import interrupts_deferred, node_environment
    from helio_optics.node_kit.processes import NodeProcess
    process = NodeProcess('helio_control', 'view_bridge', {
        'port': arguments.view_port, 'use_sim_time': sim_time, 'plan_file': plan_file},
        namespace=arguments.namespace, log_dir=log_dir, env=node_environment())
    with interrupts_deferred():
        process.start()
    print(f'[helio] Foxglove view: ws://127.0.0.1:{arguments.view_port} (log '
          f'{process.log_path})', file=sys.stderr)
    return process


def command_view(arguments):
    """Run the Foxglove view bridge in this process until Ctrl-C."""
    from helio_control.view_bridge import ViewBridgeNode
    _run_node_in_process(ViewBridgeNode, {'port': arguments.port, 'host': arguments.host,
                                          'use_sim_time': arguments.sim_time},
                         arguments.namespace)
    if ViewBridgeNode.stuck:
        os._exit(EXIT_OK)     # a client that stopped reading would hold the exit (view_bridge)
    return EXIT_OK


def _supervise(arguments, graph, describe):
    """Describe the graph (GraphError: one line), start it, supervise it until it ends."""
    from helio_control.bringup import GraphError, run_supervised
    try:
        specs = describe()
    except GraphError as error:
        raise CommandError(str(error)) from None
    log_dir = arguments.log_dir or tempfile.mkdtemp(prefix=f'helio_{graph}_logs_')
    return run_supervised(specs, arguments.namespace, log_dir,
                          stop_timeouts=(arguments.stop_timeout, arguments.stop_timeout),
                          on_started=_announce(log_dir))


def command_preview(arguments):
    """Run the preview command (helio_control.preview) with the remaining arguments."""
    from helio_control import preview
    return preview.main(arguments.preview_arguments, prog='helio preview')


def _run_node_in_process(node_class, parameters, namespace):
    """Run a node in this process with `parameters` (a parameter file, as for processes)."""
    from helio_optics.node_kit.processes import ros_arguments, write_parameter_file
    from helio_optics.node_kit.runner import run_node
    with tempfile.TemporaryDirectory(prefix='helio_parameters_') as folder:
        path = write_parameter_file(os.path.join(folder, 'parameters.yaml'), parameters)
        run_node(node_class, ['helio'] + ros_arguments(path, namespace=namespace))


def command_record(arguments):
    """Record the graph's topics into a bag (until Ctrl-C), or recover a crashed bag."""
    from helio_control.bag_files import recover_bag
    if arguments.recover:
        kept = recover_bag(arguments.recover)
        print(f'{arguments.recover}: ' + ('complete already' if kept is None else
                                          f'recovered, {kept} messages kept'))
        return EXIT_OK
    if not arguments.out:
        raise UsageError('record needs --out DIR (or --recover BAG)')
    from helio_control.recorder import RecorderNode
    parameters = {'output_dir': os.path.abspath(arguments.out),
                  'camera_decimation': arguments.camera_decimation,
                  'use_sim_time': arguments.sim_time, 'chunk_period': arguments.chunk_period}
    if arguments.topics:
        parameters['topics'] = arguments.topics
    _run_node_in_process(RecorderNode, parameters, arguments.namespace)
    return EXIT_OK


def command_replay(arguments):
    """Play a bag back with /clock."""
    from helio_control.bag_files import bag_file
    from helio_control.replay import ReplayerNode
    bag_file(arguments.bag)               # a clear error for a path that is no bag
    parameters = {'bag': os.path.abspath(arguments.bag), 'rate': arguments.rate,
                  'start_delay': arguments.delay}
    if arguments.exclude:
        parameters['exclude'] = arguments.exclude
    if arguments.topics:
        parameters['topics'] = arguments.topics
    view = _view_process(arguments, tempfile.mkdtemp(prefix='helio_view_logs_'), True)
    try:
        _run_node_in_process(ReplayerNode, parameters, arguments.namespace)
    finally:
        if view is not None:
            view.stop()
    return EXIT_OK


def command_report(arguments):
    """Write the run report of a run directory."""
    from helio_control.report import make_report
    report = make_report(arguments.run_dir)
    print(report.html_path)
    return EXIT_OK


def command_print(arguments):
    """Write the marker or board sheet; say what was written and what to measure."""
    from helio_control.print_sheets import board_sheet, marker_sheet, write_sheet
    try:
        if arguments.what == 'marker':
            sheet = marker_sheet(arguments.side, arguments.marker_id,
                                 arguments.dictionary or 'DICT_4X4_50', arguments.paper,
                                 arguments.dpi)
        else:
            try:
                squares = tuple(int(v) for v in arguments.squares.lower().split('x'))
            except ValueError:
                squares = ()
            if len(squares) != 2:
                raise ValueError(f'--squares is COLUMNSxROWS, e.g. 7x5, not '
                                 f'{arguments.squares!r}')
            sheet = board_sheet(squares, arguments.square, arguments.marker,
                                arguments.dictionary or 'DICT_5X5_100', arguments.paper,
                                arguments.dpi)
        write_sheet(sheet, arguments.out)
    except (ValueError, OSError) as error:
        raise CommandError(str(error)) from None
    print(f'{arguments.out} written ({arguments.paper}, {arguments.dpi} dpi): '
          + '; '.join(sheet.text[:2]))
    return EXIT_OK


def command_udev(arguments):
    """Print the udev rule of the serial devices; with --install, write and load it."""
    from helio_control.udev_rules import RULES_PATH, udev_rules
    text = udev_rules()
    if not arguments.install:
        print(text, end='')
        return EXIT_OK
    if os.geteuid() != 0:
        raise CommandError(f'writing {RULES_PATH} needs root: run "sudo $(which helio) udev '
                           '--install", or print the rule with "helio udev" and install it '
                           'yourself')
    with open(RULES_PATH, 'w') as stream:
        stream.write(text)
    for command in (['udevadm', 'control', '--reload-rules'], ['udevadm', 'trigger']):
        subprocess.run(command, check=True)
    print(f'{RULES_PATH} written and loaded; add yourself to the dialout group once: sudo '
          'usermod -aG dialout $USER (then log in again)', file=sys.stderr)
    return EXIT_OK


# ---------------------------------------------------------------------------- paint
class ProgressBar:
    """One line on a terminal: dots done of total, phase, T_max, N_p, ETA."""

    def __init__(self, stream=None, width=30):
        """Write to `stream` (default stderr)."""
        self.stream = stream or sys.stderr
        self.width = width

    def line(self, feedback):
        """Return the progress line for a PaintPattern feedback."""
        total = max(int(feedback.total), 0)
        done = min(int(feedback.index), total)
        filled = int(round(self.width * done / total)) if total else 0
        eta = (f'{feedback.eta / 60:.1f} min' if math.isfinite(feedback.eta) and
               feedback.eta > 0 else '?')
        return (f'[{"#" * filled}{"." * (self.width - filled)}] {done}/{total} dots  '
                f'{feedback.phase:<14} T_max {feedback.t_max:6.1f} degC  N_p {feedback.n_p:3d}'
                f'  ETA {eta}')

    def __call__(self, feedback_message):
        """
        Show one feedback (the action client's feedback callback).

        On a terminal the line is redrawn in place; into a file or pipe a line is written
        only when the dot or the phase changes, so a log stays readable.
        """
        feedback = getattr(feedback_message, 'feedback', feedback_message)
        if self.stream.isatty():
            print(self.line(feedback), end='\r', file=self.stream, flush=True)
            return
        step = (feedback.index, feedback.phase)
        if step != getattr(self, '_last_step', None):
            self._last_step = step
            print(self.line(feedback), file=self.stream, flush=True)


def default_run_dir(prefix=''):
    """Return runs/<prefix><UTC time> under the current directory."""
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime('%Y%m%dT%H%M%SZ')
    return os.path.join('runs', prefix + stamp)


def command_paint(arguments, action_type):
    """Send the PaintPattern goal; start the simulated graph when no painter answers."""
    picture = resolve_picture(arguments.picture) if arguments.picture else ''
    goal = build_goal(action_type.Goal, arguments, picture)
    if not picture and not list(getattr(goal, 'points', [])):
        raise UsageError('paint needs a PICTURE or --points')
    run_dir = os.path.abspath(arguments.out or default_run_dir())
    os.makedirs(run_dir, exist_ok=True)
    if hasattr(goal, 'run_dir') and not goal.run_dir:
        goal.run_dir = run_dir
    session = PaintSession(arguments, action_type, run_dir)
    return session.run(goal)


class PaintSession:
    """The client side of one painting: graph, recorder, goal, progress, report."""

    def __init__(self, arguments, action_type, run_dir):
        """Keep the options; nothing starts yet."""
        self.arguments = arguments
        self.action_type = action_type
        self.run_dir = run_dir
        self.group = None
        self.specs = ()
        self.recorder = None
        self.view = None
        self.interrupted = threading.Event()

    def run(self, goal):
        """Paint; return the exit status."""
        import rclpy
        from helio_optics.node_kit.client_graph import ClientGraph
        with ClientGraph('helio_paint', namespace=self.arguments.namespace) as graph:
            try:
                if self.arguments.sim:
                    client = self._painter_or_simulation(graph, goal)
                else:
                    # never the simulator unless asked: a rig's graph in another domain or
                    # namespace, or slow to start, is not painted in a simulation
                    client = connect_action(
                        graph, self.action_type, 'paint', self.arguments.connect_timeout,
                        'painter', START_THE_GRAPH + ', check ROS_DOMAIN_ID and --namespace, '
                        'or add --sim to paint in the simulated world')
                if self.group is None and self.arguments.set:
                    raise CommandError(
                        '--set sets the parameters of the simulated graph that helio paint '
                        'starts, but a painter already answers on '
                        f'{graph.helper.resolve_topic_name("paint")}: stop that graph, or set '
                        'its parameters there')
                self._start_recorder()
                self.view = _view_process(self.arguments, self.log_dir, self.group is not None,
                                          os.path.join(self.run_dir, 'plan.json'))
                return self._paint(graph, client, goal)
            finally:
                self._stop(rclpy)

    def _painter_or_simulation(self, graph, goal):
        """Return the paint client: of the painter that answers, else of a started sim graph."""
        try:
            return connect_action(graph, self.action_type, 'paint',
                                  self.arguments.connect_timeout, 'painter')
        except CommandError:
            pass                      # none: the simulated graph is started for this goal
        self._start_graph()
        if hasattr(goal, 'fresh'):
            goal.fresh = True         # a new simulated panel: nothing is burnt yet
        try:
            client = connect_action(graph, self.action_type, 'paint',
                                    self.arguments.start_timeout, 'painter',
                                    f'the simulated graph started without one (logs: '
                                    f'{self.log_dir})')
        except CommandError:
            self._graph_check()       # a node that died is the better reason
            raise
        self._wait_until_up(graph)
        return client

    @property
    def log_dir(self):
        """Return where the started processes log."""
        return os.path.join(self.run_dir, 'logs')

    def _start_graph(self):
        from helio_control.bringup import interrupts_deferred, simulated_graph, start_graph
        print('[helio] no painter is running: starting the simulated graph', file=sys.stderr)
        overrides = _overrides(self.arguments.set)
        world = overrides.setdefault('sim_world', {})
        world.setdefault('real_time_factor', self.arguments.real_time_factor)
        world['output_dir'] = self.run_dir
        port_dir = tempfile.mkdtemp(prefix='helio_paint_ports_')
        with interrupts_deferred():     # no node started but not kept for stopping
            self.specs = simulated_graph(port_dir, overrides=overrides)
            self.group = start_graph(self.specs, self.arguments.namespace, self.log_dir)

    def _wait_until_up(self, graph):
        """Wait until the started graph's nodes spin and its drivers hold their devices."""
        from helio_control.bringup import wait_until_up
        from helio_optics.node_kit.client_graph import GraphFailure, GraphTimeout
        try:
            wait_until_up(graph, self.specs, self.arguments.start_timeout)
        except (GraphTimeout, GraphFailure) as error:
            self._graph_check()
            raise CommandError(f'the simulated graph did not come up: {error} '
                               f'(logs: {self.log_dir})') from None

    def _graph_check(self):
        from helio_optics.node_kit.processes import NodeProcessError
        if self.group is not None:
            try:
                self.group.check()
            except NodeProcessError as error:
                raise CommandError(str(error).splitlines()[0] + f' (logs: {self.log_dir})') \
                    from None

    def _start_recorder(self):
        if self.arguments.no_record:
            return
        from helio_control.bringup import interrupts_deferred
        from helio_control.recorder import Recorder
        self.recorder = Recorder(os.path.join(self.run_dir, 'recording'),
                                 camera_decimation=self.arguments.camera_decimation,
                                 namespace=self.arguments.namespace,
                                 use_sim_time=self.group is not None,
                                 log_dir=self.log_dir,
                                 plan_file=os.path.join(self.run_dir, 'plan.json'))
        with interrupts_deferred():
            self.recorder.process.start()
        self.recorder.start_wait()

    def _paint(self, graph, client, goal):
        from action_msgs.msg import GoalStatus
        handle = graph.send_goal(client, goal, ProgressBar(), self.arguments.connect_timeout)
        if not handle.accepted:
            raise CommandError('the painter rejected the goal (see its log)')
        future = graph.result_of(graph.executor.create_task(handle.get_result_async),
                                 self.arguments.connect_timeout, 'the result request')
        finished = threading.Event()
        future.add_done_callback(lambda _: finished.set())
        try:
            while not finished.wait(0.5):
                self._graph_check()         # a dead node ends the wait with its name
        except KeyboardInterrupt:
            print('\n[helio] Ctrl-C: cancelling the goal (the lens retreats)', file=sys.stderr)
            graph.cancel_goal(handle, 30.0)
            graph.result_of(future, self.arguments.cancel_timeout, 'the cancelled result')
            self.interrupted.set()
            return EXIT_INTERRUPTED
        response = future.result()
        result = response.result
        print(file=sys.stderr)
        print(f'[helio] {result.message} ({result.dots_burnt} burnt, {result.dots_skipped} '
              f'skipped, {result.duration:.0f} s)', file=sys.stderr)
        return EXIT_OK if response.status == GoalStatus.STATUS_SUCCEEDED and \
            result.success else EXIT_FAILED

    def _stop(self, rclpy):
        if self.view is not None:
            self.view.stop()
        if self.recorder is not None:
            self.recorder.stop()
        if self.group is not None:
            self.group.stop()
        if os.path.exists(os.path.join(self.run_dir, 'journal.jsonl')):
            from helio_control.report import make_report
            report = make_report(self.run_dir)
            print(f'[helio] report: {report.html_path}')


# ---------------------------------------------------------------------------- parser
VIEW_PORT = 8765                 # Foxglove's usual WebSocket port


def _port(text):
    value = int(text)
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f'{text} is no port (0..65535)')
    return value


def view_options(command):
    """Add --view and --view-port (the Foxglove view bridge beside the graph)."""
    command.add_argument('--view', action='store_true', help='serve the live Foxglove view '
                         'beside it (as "helio view")')
    command.add_argument('--view-port', type=_port, default=VIEW_PORT,
                         help=f'WebSocket port of --view (default {VIEW_PORT})')


class UsageError(Exception):
    """A usage problem found after parsing (exit status 2)."""


def build_parser(action_type=None):
    """Return the argument parser of ``helio`` and its sub-commands."""
    parser = argparse.ArgumentParser(prog='helio', description='Paint with the sun: run the '
                                     'graph, paint, record, replay and report.')
    commands = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)

    def graph_options(command):
        command.add_argument('--namespace', default='', help='namespace of every node')
        command.add_argument('--nodes', nargs='+', help='start only these nodes')
        command.add_argument('--set', action='append', metavar='NODE.PARAM=VALUE',
                             help='override a node parameter (YAML value); repeatable')
        command.add_argument('--log-dir', help='node logs (default: a temporary folder)')
        command.add_argument('--stop-timeout', type=float, default=10.0,
                             help='seconds for each step SIGINT, SIGTERM before SIGKILL')

    sim = commands.add_parser('sim', help='start the simulated graph (Ctrl-C stops it)',
                              description='Start every node of the simulated rig as its own '
                              'process and supervise them.')
    graph_options(sim)
    sim.add_argument('--real-time-factor', type=_finite_float, default=1.0,
                     help='simulated seconds per wall second (0: as fast as possible)')
    sim.add_argument('--out', help='sim_world writes canvas.png and dots.csv here at the end')
    sim.add_argument('--port-dir', help="where the emulated devices' ports are made")
    view_options(sim)
    sim.set_defaults(handler=command_sim)

    rig = commands.add_parser('rig', help='start the hardware graph (Ctrl-C stops it)',
                              description='Start the graph on the real rig. The camera '
                              'drivers must publish rgb/image_raw + rgb/camera_info and '
                              'thermal/image_raw (16UC1 centikelvin) + thermal/camera_info.')
    graph_options(rig)
    rig.add_argument('--dobot-port', required=True,
                     help='serial port of the Dobot, or "auto" (found by its USB ids)')
    rig.add_argument('--servo-port', required=True, help='serial port of the servo controller')
    for kind in ('rgb', 'thermal'):
        rig.add_argument(f'--{kind}-camera', metavar='PKG/EXE',
                         help=f'{kind} camera driver to start (image_raw and camera_info '
                              f'remapped into {kind}/)')
        rig.add_argument(f'--{kind}-camera-param', action='append', metavar='NAME=VALUE',
                         help=f'parameter of the {kind} camera driver; repeatable')
    view_options(rig)
    rig.set_defaults(handler=command_rig)

    preview = commands.add_parser('preview', add_help=False, help='plan a picture: '
                                  'preview.png and plan.json (no graph needed)',
                                  description='helio preview PICTURE --out DIR [options]; '
                                  '"helio preview --help" lists the options.')
    preview.add_argument('preview_arguments', nargs=argparse.REMAINDER)
    preview.set_defaults(handler=command_preview)

    paint = commands.add_parser('paint', help='paint a picture through the paint action',
                                description='Send the PaintPattern goal to a running graph '
                                '(with --sim: start the simulated graph when none answers); '
                                'record the run and write its report. Ctrl-C cancels the '
                                'goal.')
    paint.add_argument('picture', nargs='?', default='',
                       help='picture file or sample:text, sample:logo, sample:portrait')
    paint.add_argument('--out', help='run directory (default: runs/<UTC time>)')
    paint.add_argument('--namespace', default='', help='namespace of the graph')
    paint.add_argument('--connect-timeout', type=float, default=5.0,
                       help='seconds to wait for a running painter')
    paint.add_argument('--start-timeout', type=float, default=60.0,
                       help='seconds for a started graph to offer the paint action')
    paint.add_argument('--cancel-timeout', type=float, default=60.0,
                       help='seconds to wait for the result after Ctrl-C')
    paint.add_argument('--sim', action='store_true',
                       help='when no painter answers, start the simulated graph and paint '
                            'there (without it: exit 1 naming the domain and namespace)')
    paint.add_argument('--set', action='append', metavar='NODE.PARAM=VALUE',
                       help='override a node parameter of a started simulated graph (YAML '
                            'value), e.g. sim_world.build=drawn; repeatable')
    paint.add_argument('--no-record', action='store_true', help='do not record the run')
    paint.add_argument('--camera-decimation', type=_positive_int, default=5,
                       help='record every N-th camera message')
    paint.add_argument('--real-time-factor', type=_finite_float, default=6.0,
                       help='of a started simulated graph (0: as fast as the graph keeps up, '
                            'in lockstep with every node that reads it)')
    view_options(paint)
    if action_type is not None:
        add_goal_options(paint, action_type.Goal)
    paint.set_defaults(handler=lambda arguments: command_paint(arguments, action_type))

    record = commands.add_parser('record', help="record the graph's topics into a bag",
                                 description='Record every topic (camera topics decimated) '
                                 'into a rosbag2/MCAP bag until Ctrl-C.')
    record.add_argument('--out', help='bag directory to create')
    record.add_argument('--recover', metavar='BAG', help='complete a bag a crash left open')
    record.add_argument('--topics', nargs='+', help='only these topics')
    record.add_argument('--camera-decimation', type=_positive_int, default=5,
                        help='keep every N-th camera message')
    record.add_argument('--chunk-period', type=float, default=2.0,
                        help='longest time a chunk stays open (what a crash loses) [s]')
    record.add_argument('--sim-time', action='store_true',
                        help='stamp messages with /clock (simulated graphs)')
    record.add_argument('--namespace', default='', help='namespace to resolve topics in')
    record.set_defaults(handler=command_record)

    replay = commands.add_parser('replay', help='play a bag back with /clock',
                                 description='Publish the messages of a bag with /clock at a '
                                 'rate; ends when the bag is played.')
    replay.add_argument('bag', help='bag directory')
    replay.add_argument('--rate', type=_finite_float, default=1.0,
                        help='bag seconds per wall second')
    replay.add_argument('--delay', type=_finite_float, default=0.5, metavar='SECONDS',
                        help='wall time to let subscribers discover the publishers before '
                        'playing (as ros2 bag play --delay; default 0.5)')
    replay.add_argument('--exclude', nargs='+', metavar='TOPIC', help='topics not played')
    replay.add_argument('--topics', nargs='+', help='only these topics')
    replay.add_argument('--namespace', default='', help='namespace to play into')
    view_options(replay)
    replay.set_defaults(handler=command_replay)

    view = commands.add_parser('view', help='the live Foxglove view of a running graph',
                               description='Serve the graph to the Foxglove app over its '
                               'WebSocket protocol (annotated camera images, 3D scene, '
                               'plots) until Ctrl-C; open it with the layout '
                               'config/foxglove/helio.json.')
    view.add_argument('--port', type=_port, default=VIEW_PORT,
                      help=f'WebSocket port (default {VIEW_PORT}; 0: any free port, logged)')
    view.add_argument('--host', default='127.0.0.1',
                      help='address to bind (default 127.0.0.1: this machine only)')
    view.add_argument('--namespace', default='', help='namespace of the graph')
    view.add_argument('--sim-time', action='store_true', help='run on /clock')
    view.set_defaults(handler=command_view)

    report = commands.add_parser('report', help='write the report of a run directory',
                                 description='Write summary.json, plots and report.html '
                                 'into RUN_DIR.')
    report.add_argument('run_dir', help='run directory (runs/<UTC time>)')
    report.set_defaults(handler=command_report)

    sheet = commands.add_parser(
        'print', help='a sheet to print at 1:1: the ground marker or a ChArUco board',
        description='Write the ground marker (or a ChArUco calibration board) at its true '
        'size on an A4 or letter page, with a 100 mm scale bar, as PNG or PDF: print it at '
        '100 %%, measure it, and enter the measured size in the configuration.')
    sheet.add_argument('what', choices=('marker', 'board'), help='the marker or the board')
    sheet.add_argument('--out', required=True, help='file to write (.png or .pdf)')
    sheet.add_argument('--paper', choices=('a4', 'letter'), default='a4', help='page size')
    sheet.add_argument('--dpi', type=_positive_int, default=600, help='pixels per inch')
    sheet.add_argument('--side', type=_finite_float, default=0.04,
                       help="marker: black square [m] (spot_detector's marker.side)")
    sheet.add_argument('--id', type=_non_negative_int, default=0, dest='marker_id',
                       help="marker: ArUco id (spot_detector's marker.id)")
    sheet.add_argument('--dictionary', default=None,
                       help='ArUco dictionary (marker: DICT_4X4_50; board: DICT_5X5_100)')
    sheet.add_argument('--squares', default='7x5', help='board: columns x rows')
    sheet.add_argument('--square', type=_finite_float, default=0.025,
                       help='board: square side [m]')
    sheet.add_argument('--marker', type=_finite_float, default=0.018,
                       help="board: its markers' side [m]")
    sheet.set_defaults(handler=command_print)

    udev = commands.add_parser('udev', help="the udev rule of the rig's serial devices",
                               description='Print the udev rule that gives the Dobot and the '
                               'Maestro to the dialout group as /dev/helio_dobot and '
                               '/dev/helio_maestro; --install writes and loads it (root).')
    udev.add_argument('--install', action='store_true',
                      help='write /etc/udev/rules.d/99-helio.rules and reload udev (root)')
    udev.set_defaults(handler=command_udev)

    calibrations = commands.add_parser(
        'calibrations', help='list the saved calibrations',
        description='List the calibration directory: each calibration, when and by what it was '
        'made, its residuals, and whether it is used for this rig file (one made for another '
        'rig description is refused by the nodes). Exit 1 when one is refused.')
    calibrations.add_argument('--dir', help='calibration directory (default '
                              "~/.helio/calibration, the lens planner's calibration_dir)")
    calibrations.add_argument('--rig', help="rig file (default: the workspace's config/rig.yaml)")
    calibrations.set_defaults(handler=command_calibrations)

    calibrate = commands.add_parser(
        'calibrate', help='run a calibration on the running graph',
        description="Send the calibration goal to the running graph's lens planner, print "
        'its progress and result. "rig": the build errors from the marker and the spot '
        '(CalibrateRig, about 5 minutes of rig time; each fitted term with its rig-file '
        'value and uncertainty, and the terms the poses cannot see); "world": T_robot_world '
        'from the marker (CalibrateWorld). "camera": the RGB camera\'s intrinsics from at '
        'most 25 views of a printed ChArUco board ("helio print board") laid on the panel, '
        'moved to through the drivers; writes camera_info/rgb.yaml into the calibration '
        "directory (usb_cam's camera_info_url, spot_detector's camera_info_file). 'dots': "
        'a row of test dots on the margin outside the canvas at several N_p targets (one '
        'PaintPattern goal each), their diameters as the RGB camera measured them and their '
        "dwells fitted (d^2 linear in N_p) and saved as dots.yaml in the painter's "
        "calibration_dir: a goal's dot_radius is then the burnt dot's width. Exit 1 "
        'when it fails or is refused.')
    calibrate.add_argument('what', choices=('rig', 'world', 'camera', 'dots'),
                           help='which calibration')
    calibrate.add_argument('--poses', type=_non_negative_int, default=0,
                           help="poses to visit (0: the lens planner's parameter)")
    calibrate.add_argument('--no-apply', action='store_true',
                           help='measure only: do not publish or save the result')
    calibrate.add_argument('--namespace', default='', help='namespace of the graph')
    calibrate.add_argument('--connect-timeout', type=_finite_float, default=10.0,
                           help='seconds to wait for the lens planner')
    calibrate.add_argument('--timeout', type=_finite_float, default=1800.0,
                           help='longest wait for the result [s]')
    board = calibrate.add_argument_group('camera: the board as printed and where it lies')
    board.add_argument('--board-squares', type=_positive_int, nargs=2, default=[7, 5],
                       metavar=('COLUMNS', 'ROWS'), help='squares (default 7 5)')
    board.add_argument('--board-square', type=_finite_float, default=0.025, metavar='M',
                       help='square side as measured [m] (default 0.025)')
    board.add_argument('--board-marker', type=_finite_float, default=0.018, metavar='M',
                       help='marker side as measured [m] (default 0.018)')
    board.add_argument('--board-dictionary', default='DICT_5X5_100',
                       help='ArUco dictionary of its markers (default DICT_5X5_100)')
    board.add_argument('--board-centre', type=_finite_float, nargs=2, default=[0.1, 0.1],
                       metavar=('X', 'Y'), help="the board's centre on the panel, world frame "
                       "(the marker's axes) [m] (default 0.1 0.1: over the canvas)")
    board.add_argument('--board-yaw', type=_finite_float, default=0.0, metavar='DEG',
                       help="the board's x axis from the marker's [deg] (default 0)")
    board.add_argument('--fov', type=_finite_float, default=70.0, metavar='DEG',
                       help="the camera's horizontal field of view, the fit's start when "
                       'camera_info is uncalibrated [deg] (default 70)')
    board.add_argument('--calibration-dir', help="where to write (default: the lens planner's "
                       "calibration_dir; dots: the painter's; else ~/.helio/calibration)")
    board.add_argument('--camera-name', default='rgb_camera',
                       help="camera_name in the file (usb_cam's camera_name; default "
                       'rgb_camera)')
    dots = calibrate.add_argument_group('dots: the row of test dots')
    dots.add_argument('--n-p-targets', type=_positive_int, nargs='+', default=[15, 22, 30, 40],
                      metavar='N', help='N_p targets of the test dots (default 15 22 30 40)')
    dots.add_argument('--dots-per-target', type=_positive_int, default=2, metavar='K',
                      help='test dots at each target (default 2)')
    dots.add_argument('--row', type=_finite_float, nargs=2, default=[0.06, 0.14],
                      metavar=('X', 'Y'), help='the first test dot, world frame [m] (default '
                      '0.06 0.14: 1 cm above the default canvas); the row runs '
                      'along +x: choose bare wood outside the canvas')
    dots.add_argument('--pitch', type=_finite_float, default=0.005, metavar='M',
                      help='test dots this far apart [m] (default 0.005)')
    dots.add_argument('--out', help='run directories of the test goals (default '
                      'runs/calibrate_dots_<UTC time>)')
    calibrate.set_defaults(handler=command_calibrate)

    doctor = commands.add_parser(
        'doctor', help='check a running graph: a checklist with a fix for each finding',
        description='Listen to the running graph for a few seconds and check it: devices '
        'connected, homed, without alarms; the emergency stop released; each camera at its '
        'rate with a calibrated camera_info; a thermal read-out that reaches the pyrolysis '
        'threshold; the marker in view; a site file that is not the sample; the clocks; the '
        'calibrations made for this rig. Moves nothing. Exit 0 when nothing FAILs, else 1.')
    doctor.add_argument('--namespace', default='', help='namespace of the graph')
    doctor.add_argument('--window', type=_finite_float, default=3.0, metavar='SECONDS',
                        help='how long to listen (default 3)')
    doctor.add_argument('--calibration-dir', help='calibration directory (default: the lens '
                        "planner's calibration_dir parameter)")
    doctor.add_argument('--site', metavar='FILE', help='site file to check (default: the sun '
                        "estimator's and lens planner's site_file parameters)")
    doctor.add_argument('--rgb-rate', type=_finite_float, default=5.0, metavar='HZ',
                        help='expected RGB image rate (default 5, the simulated camera)')
    doctor.add_argument('--thermal-rate', type=_finite_float, default=8.7, metavar='HZ',
                        help='expected thermal image rate (default 8.7, a Lepton)')
    doctor.add_argument('--rate-tolerance', type=_finite_float, default=0.7,
                        help='a rate below this share of the expected one fails')
    doctor.add_argument('--discovery-timeout', type=_finite_float, default=10.0,
                        metavar='SECONDS', help='longest wait for the graph to be discovered '
                        'before the window starts (default 10)')
    doctor.add_argument('--json', metavar='PATH', help='also write the findings as JSON')
    doctor.set_defaults(handler=command_doctor)

    for name, engage, text in (
            ('stop', True, 'EMERGENCY STOP: the drivers stop, the wrist turns the lens off '
             'the sun, every goal ends and new ones are refused until "helio reset"'),
            ('reset', False, 'release the emergency stop: goals are taken again')):
        command = commands.add_parser(name, help=text.split(':')[0].lower(), description=text)
        command.add_argument('--namespace', default='', help='namespace of the graph')
        command.add_argument('--timeout', type=float, default=5.0,
                             help="seconds to wait for the servo driver's service")
        command.set_defaults(handler=lambda arguments, engage=engage:
                             command_emergency_stop(arguments, engage))
    add_sky_parser(commands)
    return parser


def command_sky(arguments):
    """Print when the sun serves the canvas on a day, and the heading with the most hours."""
    import json
    import time
    import zoneinfo
    from helio_control import sky
    from helio_control.picture_options import CANVAS_OPTIONS
    from helio_control.plan import load_plan_options, PlanOptionsError
    from helio_optics.ephemeris import load_site
    from helio_optics.node_kit.deployment import deployment_file_or_default
    from helio_optics.node_kit.deployment import rig_file_or_default
    from helio_optics.rig_kinematics import load_rig_parameters, Rig
    started = time.perf_counter()
    try:
        site_file = deployment_file_or_default(arguments.site or '', 'site.yaml', '--site')
        site = load_site(site_file)
        rig = Rig(load_rig_parameters(rig_file_or_default(arguments.rig or '')))
        options = load_plan_options(arguments.picture_config, **{
            name: getattr(arguments, name) for name in CANVAS_OPTIONS})
        options.validate()
        settings = sky.SkySettings.from_plan_options(
            options, min_elevation_deg=arguments.min_elevation,
            need_marker=arguments.marker_in_view, camera_width=arguments.camera_size[0],
            camera_height=arguments.camera_size[1], camera_fov_deg=arguments.camera_fov)
    except (OSError, ValueError, PlanOptionsError) as error:
        raise CommandError(str(error)) from None
    if arguments.timezone:
        try:
            tz = zoneinfo.ZoneInfo(arguments.timezone)
        except (zoneinfo.ZoneInfoNotFoundError, ValueError):
            raise CommandError(f'unknown time zone {arguments.timezone!r} (an IANA name such '
                               'as Europe/Berlin)') from None
        tz_note = f' ({arguments.timezone})'
    elif arguments.utc_offset is not None:
        tz = datetime.timezone(datetime.timedelta(hours=arguments.utc_offset))
        tz_note = ''
    else:
        tz = sky.default_timezone(site)
        tz_note = (" (the site's longitude, no daylight saving: --timezone NAME or "
                   '--utc-offset H for the clock on your wall)')
    date = arguments.date or datetime.datetime.now(tz).date()
    model = sky.SkyModel(rig, settings)
    headings = [k * arguments.heading_step for k in
                range(int(math.ceil(360.0 / arguments.heading_step - 1e-9)))]
    scan = sky.heading_scan(model, site, date, tz, headings, arguments.step * 60.0)
    best = sky.best_heading(scan, prefer=arguments.heading)
    heading = best[0] if arguments.heading is None else arguments.heading
    day = sky.sky_day(model, site, date, tz, heading, arguments.step * 60.0)
    lines = sky.report_lines(day, scan, best, settings, site_file, tz_note)
    if arguments.heading is None:
        lines.insert(1, f'no --heading given: the table is for the best heading, '
                        f'{heading:.0f} deg')
    print('\n'.join(lines))
    run_time = time.perf_counter() - started
    print(f'(computed in {run_time:.1f} s)')
    if arguments.json:
        with open(arguments.json, 'w') as stream:
            json.dump(sky.report_dict(day, scan, best, settings, site_file, run_time), stream,
                      indent=1)
    if not day.hours:
        reasons = [sample.verdict.reason for sample in day.samples]
        common = max(set(reasons), key=reasons.count) if reasons else 'the sun does not rise'
        other = (f'heading {best[0]:.0f} deg would give {best[1]:.1f} h' if best[1] else
                 f'no heading in steps of {arguments.heading_step:g} deg does')
        raise CommandError(f'the sun does not serve this canvas on {date.isoformat()} at '
                           f'heading {heading:.0f} deg (mostly: {common}); {other}')
    return EXIT_OK


def _date(text):
    try:
        return datetime.date.fromisoformat(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'a date is YYYY-MM-DD, not {text!r}') from None


def _size(text):
    try:
        width, height = (int(v) for v in text.lower().split('x'))
    except ValueError:
        raise argparse.ArgumentTypeError(f'a size is WIDTHxHEIGHT in pixels, not {text!r}') \
            from None
    if width < 1 or height < 1:
        raise argparse.ArgumentTypeError(f'a size must be positive, not {text!r}')
    return width, height


def add_sky_parser(commands):
    """Add the ``sky`` sub-command to the sub-parsers `commands`."""
    from helio_control.picture_options import add_option_arguments, CANVAS_OPTIONS
    sky = commands.add_parser(
        'sky', help='when the sun serves the canvas on a day, and the best heading',
        description='For the site, a date and the rig heading: the hours in which every canvas '
        'dot is within reach (Eqs 14-15, the rig file) and the sun sweep can estimate the sun '
        '(its lowest sun, the camera sees the spot), the windows, and the heading with the '
        'most hours. Exit 1 when the sun never serves the canvas at that heading.')
    sky.add_argument('--date', type=_date, help='local date YYYY-MM-DD (default: today)')
    sky.add_argument('--heading', type=_finite_float, metavar='DEG',
                     help="compass azimuth of the robot's x axis, clockwise from north (the "
                     "painter's refusal names the one its sun estimate implies; default: the "
                     'best heading)')
    sky.add_argument('--site', help="site file (default: the workspace's config/site.yaml)")
    sky.add_argument('--rig', help="rig file (default: the workspace's config/rig.yaml)")
    sky.add_argument('--picture-config', help='picture options file (default: '
                     'config/picture.yaml): canvas, d_lp, retreat')
    add_option_arguments(sky, CANVAS_OPTIONS, dict.fromkeys(CANVAS_OPTIONS, _finite_float))
    zone = sky.add_mutually_exclusive_group()
    zone.add_argument('--timezone', metavar='NAME', help='IANA time zone of the table, e.g. '
                      "Europe/Berlin (default: the site's longitude, 15 deg an hour)")
    zone.add_argument('--utc-offset', type=_finite_float, metavar='HOURS',
                      help='fixed UTC offset of the table, e.g. 2')
    sky.add_argument('--step', type=_positive_float, default=10.0, metavar='MIN',
                     help='minutes between samples (default 10)')
    sky.add_argument('--heading-step', type=_positive_float, default=15.0, metavar='DEG',
                     help='step of the heading scan (default 15)')
    sky.add_argument('--min-elevation', type=_finite_float, default=30.0, metavar='DEG',
                     help='lowest sun the sweep estimates (default 30: the simulated sweep '
                     'estimated 31 deg, not 26.5)')
    sky.add_argument('--marker-in-view', action='store_true',
                     help='the sweep must see the marker too (a rig without a robot-world '
                     'calibration)')
    sky.add_argument('--camera-size', type=_size, default=(640, 480), metavar='WxH',
                     help='RGB camera image size (default 640x480)')
    sky.add_argument('--camera-fov', type=_finite_float, default=70.0, metavar='DEG',
                     help='RGB camera horizontal field of view (default 70)')
    sky.add_argument('--json', metavar='PATH', help='also write the table as JSON')
    sky.set_defaults(handler=command_sky)


def command_calibrations(arguments):
    """List the saved calibrations: what, when, residuals, and whether this rig uses them."""
    from helio_control.calibration_store import list_calibrations, rig_description
    from helio_optics.node_kit.deployment import calibration_dir_or_default
    from helio_optics.node_kit.deployment import rig_file_or_default
    directory = calibration_dir_or_default(arguments.dir)
    rig_file = rig_file_or_default(arguments.rig or '')
    description = rig_description(rig_file)
    entries = list_calibrations(directory, description)
    print(f'{directory} (rig file {rig_file}, rig description {description}):')
    if not entries:
        print('  no calibration saved: the painter calibrates robot-world at its first '
              'painting; calibrate_focus measures the heating distance')
        return EXIT_OK
    for entry in entries:
        extra = ', '.join(f'{key} {value:.4g}' if isinstance(value, float) else
                          f'{key} {value}' for key, value in entry.items()
                          if key not in ('name', 'usable', 'reason', 'made_by', 'saved_at',
                                         'rig_description'))
        state = 'used' if entry['usable'] else f'REFUSED: {entry["reason"]}'
        print(f'  {entry["name"]}: saved {entry.get("saved_at", "?")} by '
              f'{entry.get("made_by", "?")}{"; " + extra if extra else ""}; {state}')
    return EXIT_OK if all(entry['usable'] for entry in entries) else EXIT_FAILED


def command_calibrate(arguments):
    """Run calibrate_rig or calibrate_world on the running graph; print the result."""
    if arguments.what == 'camera':
        return command_calibrate_camera(arguments)
    if arguments.what == 'dots':
        return command_calibrate_dots(arguments)
    from helio_msgs.action import CalibrateRig, CalibrateWorld
    from helio_optics.node_kit.client_graph import ClientGraph, GraphTimeout
    action_type, name = {'rig': (CalibrateRig, 'calibrate_rig'),
                         'world': (CalibrateWorld, 'calibrate_world')}[arguments.what]
    goal = action_type.Goal(poses=arguments.poses, apply=not arguments.no_apply)
    with ClientGraph('helio_calibrate', namespace=arguments.namespace) as graph:
        client = connect_action(graph, action_type, name, arguments.connect_timeout,
                                'lens planner')
        last = {}

        def progress(message):
            feedback = message.feedback
            if (feedback.phase, feedback.index) != (last.get('phase'), last.get('index')):
                last.update(phase=feedback.phase, index=feedback.index)
                print(f'[helio] {feedback.phase} {feedback.index + 1}/{feedback.total}',
                      file=sys.stderr, flush=True)

        try:
            response = graph.run_goal(client, goal, progress, arguments.timeout)
        except GraphTimeout:
            raise CommandError(f'{name} gave no result within {arguments.timeout:g} s') \
                from None
    result = response.result
    print(result.message)
    for term, value, prior, sigma in zip(getattr(result, 'names', ()),
                                         getattr(result, 'values', ()),
                                         getattr(result, 'rig_file', ()),
                                         getattr(result, 'sigmas', ())):
        print(f'  {term}: {value:.6g} (rig file {prior:.6g}, +- {sigma:.2g})')
    for line in getattr(result, 'unobserved', ()):
        print(f'  not observed: {line}')
    if result.saved_to:
        print(f'saved to {result.saved_to}')
    return EXIT_OK if result.success else EXIT_FAILED


def command_calibrate_camera(arguments):
    """Calibrate the RGB camera over a ChArUco board on the running graph; write its file."""
    from helio_control.camera_calibration_graph import calibrate_on_graph, GraphRig
    from helio_optics.calibration_board import BoardSpec
    from helio_optics.node_kit.client_graph import ClientGraph
    spec = BoardSpec(tuple(arguments.board_squares), arguments.board_square,
                     arguments.board_marker, arguments.board_dictionary)

    def progress(index, total, note):
        print(f'[helio] view {min(index + 1, total)}/{total}: {note}', file=sys.stderr,
              flush=True)

    with ClientGraph('helio_calibrate', namespace=arguments.namespace) as graph:
        done = calibrate_on_graph(
            graph, spec, tuple(arguments.board_centre), math.radians(arguments.board_yaw),
            arguments.poses or 25, arguments.calibration_dir,
            horizontal_fov=math.radians(arguments.fov), camera_name=arguments.camera_name,
            apply=not arguments.no_apply, progress=progress,
            graph_rig=GraphRig(graph, arguments.connect_timeout))
    for note in done.notes:
        print(note)
    run = done.run
    print(run.calibration.summary())
    sigmas = run.calibration.sigmas      # fx = fy: one focal length, its sigma fy's
    print('  one-sigma: ' + ', '.join(
        f'{"fx = fy" if name == "fy" else name} {sigmas[name]:.3g}'
        for name in ('fy', 'cx', 'cy', 'k1', 'k2') if name in sigmas))
    for index, reason in run.collected.missed:
        print(f'  pose {index + 1}: no view ({reason})')
    if done.path:
        print(f'saved to {done.path}')
    return EXIT_OK


def command_calibrate_dots(arguments):
    """Burn the test row on the running graph, fit the dot size, save dots.yaml."""
    from helio_control.dot_size_calibration import calibration_row, DotCalibrationError
    from helio_control.dot_size_calibration_graph import calibrate_dots_on_graph
    from helio_msgs.action import PaintPattern
    from helio_optics.node_kit.client_graph import ClientGraph, GraphTimeout
    try:
        goals = calibration_row(arguments.n_p_targets, arguments.dots_per_target,
                                tuple(arguments.row), arguments.pitch)
    except ValueError as error:
        raise UsageError(str(error)) from None
    out = arguments.out or default_run_dir('calibrate_dots_')
    with ClientGraph('helio_calibrate', namespace=arguments.namespace) as graph:
        client = connect_action(graph, PaintPattern, 'paint', arguments.connect_timeout,
                                'painter')
        try:
            calibration, samples, path, messages = calibrate_dots_on_graph(
                graph, client, PaintPattern.Goal, out, goals, arguments.calibration_dir,
                save=not arguments.no_apply, timeout=arguments.timeout,
                progress=lambda text: print(f'[helio] {text}', file=sys.stderr, flush=True))
        except GraphTimeout:
            raise CommandError(f'a test goal gave no result within {arguments.timeout:g} s') \
                from None
        except DotCalibrationError as error:
            raise CommandError(f'dot-size calibration failed: {error} (runs in {out})') \
                from None
    for message in messages:
        print(message)
    for sample in samples:
        law = float(calibration.diameter(sample.n_p_target))
        print(f'  N_p {sample.n_p_target}: {sample.diameter * 1e3:.2f} mm in '
              f'{sample.dwell:.1f} s (the law: {law * 1e3:.2f} mm)')
    for line in calibration.summary():
        print(line)
    if path:
        print(f'saved to {path}')
    return EXIT_OK


def command_doctor(arguments):
    """Gather facts from the running graph, print the checklist; exit 1 when a check fails."""
    import json
    from helio_control import doctor
    from helio_control.bringup import node_environment
    from helio_control.doctor_probe import gather
    if arguments.window <= 0.0:
        raise UsageError(f'--window must be > 0, not {arguments.window:g}')
    for path, option in ((arguments.site, '--site'),
                         (arguments.calibration_dir, '--calibration-dir')):
        if path and not os.path.exists(path):
            raise CommandError(f'{option} {path} does not exist')
    os.environ.update(node_environment())        # the camera images' DDS profile
    facts = gather(arguments.namespace, arguments.window, arguments.calibration_dir,
                   arguments.site and os.path.abspath(arguments.site),
                   arguments.discovery_timeout)
    settings = doctor.Settings(rgb_rate=arguments.rgb_rate,
                               thermal_rate=arguments.thermal_rate,
                               rate_tolerance=arguments.rate_tolerance)
    findings = doctor.run_checks(facts, settings)
    print(doctor.checklist_text(findings, facts), flush=True)
    if arguments.json:
        with open(arguments.json, 'w') as stream:
            json.dump(doctor.findings_json(findings), stream, indent=1)
    return EXIT_OK if doctor.passed(findings) else EXIT_FAILED


def command_emergency_stop(arguments, engage):
    """
    Engage (`engage`) or reset the graph's emergency stop through the servo driver's service.

    Without that service (no servo driver), an engage publishes the latched state itself, so
    that every node running now still stops, and exits 1 saying so.
    """
    from helio_optics.node_kit import emergency_stop
    from helio_optics.node_kit.client_graph import ClientGraph, GraphTimeout
    from std_msgs.msg import Bool
    from std_srvs.srv import Trigger
    name = emergency_stop.SERVICE if engage else emergency_stop.RESET_SERVICE
    with ClientGraph(f'helio_{arguments.command}', namespace=arguments.namespace) as graph:
        client = graph.helper.create_client(Trigger, name)
        where = graph.helper.resolve_service_name(name)
        domain = ros_domain()
        try:
            response = graph.call(client, Trigger.Request(), arguments.timeout)
        except GraphTimeout:
            if not engage:
                raise CommandError(f'no service {where} in ROS_DOMAIN_ID {domain} within '
                                   f'{arguments.timeout:g} s (is the servo driver running?)')
            publisher = graph.helper.create_publisher(Bool, emergency_stop.TOPIC,
                                                      emergency_stop.QOS)
            publisher.publish(Bool(data=True))
            acknowledged = publisher.wait_for_all_acked(
                rclpy_duration(arguments.timeout))
            listeners = publisher.get_subscription_count()
            raise CommandError(
                f'no service {where} in ROS_DOMAIN_ID {domain} within {arguments.timeout:g} s '
                f'(is the servo driver running?): published '
                f'{graph.helper.resolve_topic_name(emergency_stop.TOPIC)} = true directly, '
                f'heard by {listeners} node(s){"" if acknowledged else " (not all confirmed)"}; '
                'the wrist was NOT turned: check that the focus is off the wood')
        print(response.message)
        return EXIT_OK if response.success else EXIT_FAILED


def rclpy_duration(seconds):
    """Return an rclpy Duration of `seconds`."""
    from rclpy.duration import Duration
    return Duration(nanoseconds=int(seconds * 1e9))


def _interrupt(signum, frame):
    raise KeyboardInterrupt(signal.Signals(signum).name)


def _stop_signals_interrupt():
    """
    Make SIGINT, SIGTERM and SIGHUP a KeyboardInterrupt: Ctrl-C's path for all three.

    That path cancels the goal (the lens retreats) and stops every process helio started;
    Python's default SIGTERM would end helio at once and leave them running. SIGINT is set
    too because a shell starting helio in the background hands it SIGINT ignored.
    """
    for name in ('SIGINT', 'SIGTERM', 'SIGHUP'):
        signal.signal(getattr(signal, name), _interrupt)


def main(args=None):
    """Run ``helio``; return the exit status."""
    args = sys.argv[1:] if args is None else list(args)
    try:
        from helio_msgs.action import PaintPattern
    except ImportError:
        PaintPattern = None     # noqa: N806 - paint then explains
    parser = build_parser(PaintPattern)
    # exits 2 on bad usage; `preview` hands everything on to its own parser, its leading
    # options included (argparse's REMAINDER leaves those out: "helio preview --help")
    arguments, unknown = parser.parse_known_args(args)
    if arguments.command == 'preview':
        arguments.preview_arguments = unknown + arguments.preview_arguments
    elif unknown:
        parser.error(f'unrecognized arguments: {" ".join(unknown)}')
    _stop_signals_interrupt()
    try:
        if arguments.command == 'paint' and PaintPattern is None:
            raise CommandError('helio_msgs is not installed (is the workspace sourced?)')
        return arguments.handler(arguments)
    except UsageError as error:
        parser.print_usage(sys.stderr)
        print(f'helio {arguments.command}: error: {error}', file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f'\nhelio {arguments.command}: interrupted', file=sys.stderr)
        return EXIT_INTERRUPTED
    except (CommandError, OSError, ValueError, RuntimeError, AssertionError) as error:
        message = ' '.join(str(error).split()) or type(error).__name__
        print(f'helio {arguments.command}: error: {message}', file=sys.stderr)
        return EXIT_FAILED


if __name__ == '__main__':
    sys.exit(main())
