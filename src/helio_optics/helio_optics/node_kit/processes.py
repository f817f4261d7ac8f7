"""
Nodes as separate processes, the way a user runs them (``ros2 run`` / a launch file).

``NodeProcess`` starts one installed executable (``<prefix>/lib/<package>/<executable>``,
found through the ament index like ``ros2 run``) with ``--ros-args``: a parameter file written
for it, remaps, a namespace, and its output captured to a log file. ``ProcessGroup`` starts
several, notices at once when one dies (with its last log lines), and stops them all cleanly:
SIGINT, then SIGTERM, then SIGKILL, each after a timeout; no process is left behind. A node
also gets SIGTERM from the kernel when the process that started it dies (killed with
SIGKILL, say, where it cannot stop its nodes): each is started through util-linux's
``setpriv --pdeathsig TERM`` where that is installed. Its nodes used to run on, orphaned.

No rclpy import: tests, the bringup runner and the command line share this.
"""

import collections
import os
import shutil
import signal
import subprocess
import tempfile
import threading
import time

import yaml


class NodeProcessError(RuntimeError):
    """A node process could not start, or died."""


def executable_path(package, executable):
    """Return the installed path of `executable` of `package`, as ``ros2 run`` finds it."""
    from ament_index_python.packages import get_package_prefix, PackageNotFoundError
    try:
        prefix = get_package_prefix(package)
    except PackageNotFoundError:
        raise NodeProcessError(f'package {package!r} is not installed (is the workspace built '
                               'and sourced?)') from None
    path = os.path.join(prefix, 'lib', package, executable)
    if not os.access(path, os.X_OK):
        raise NodeProcessError(f'{package} has no executable {executable!r} ({path})')
    return path


def ros_arguments(parameter_file=None, remaps=None, namespace='', name='', log_level=''):
    """Return the ``--ros-args ...`` list for a node process."""
    arguments = ['--ros-args']
    if name:
        arguments += ['-r', f'__node:={name}']
    if namespace:
        arguments += ['-r', f'__ns:={namespace}']
    for source, target in (remaps or {}).items():
        arguments += ['-r', f'{source}:={target}']
    if parameter_file:
        arguments += ['--params-file', parameter_file]
    if log_level:
        arguments += ['--log-level', log_level]
    return arguments


def write_parameter_file(path, parameters):
    """Write `parameters` (nested or dotted names) as a ROS 2 parameter file for any node."""
    tree = {}
    for name, value in parameters.items():
        branch = tree
        *parents, leaf = name.split('.')
        for part in parents:
            branch = branch.setdefault(part, {})
        branch[leaf] = value
    with open(path, 'w') as stream:
        yaml.safe_dump({'/**': {'ros__parameters': tree}}, stream, default_flow_style=False)
    return path


class NodeProcess:
    """One node executable in its own process; see the module docstring."""

    def __init__(self, package, executable, parameters=None, parameter_files=(), remaps=None,
                 namespace='', name='', log_dir=None, env=None, log_level=''):
        """Describe the process; `start()` runs it. Logs go to `log_dir` (default: a tmpdir)."""
        self.package, self.executable = package, executable
        self.label = name or executable
        self.parameters = dict(parameters or {})
        self.parameter_files = list(parameter_files)
        self.remaps = dict(remaps or {})
        self.namespace, self.name, self.log_level = namespace, name, log_level
        self.log_dir = log_dir or tempfile.mkdtemp(prefix=f'helio_{self.label}_')
        self.env = env
        self.log_path = os.path.join(self.log_dir, f'{self.label}.log')
        self.process = None

    def command(self):
        """Return the command line that starts the node."""
        command = [executable_path(self.package, self.executable), '--ros-args']
        for path in self.parameter_files:
            command += ['--params-file', path]
        if self.parameters:
            path = write_parameter_file(os.path.join(self.log_dir, f'{self.label}.params.yaml'),
                                        self.parameters)
            command += ['--params-file', path]
        extra = ros_arguments(None, self.remaps, self.namespace, self.name, self.log_level)
        return command + extra[1:]

    def start(self):
        """Start the process (its own process group, SIGTERM when we die); return self."""
        os.makedirs(self.log_dir, exist_ok=True)
        command = self.command()
        setpriv = shutil.which('setpriv')
        if setpriv:         # the kernel signals it when this thread's process dies
            command = [setpriv, '--pdeathsig', 'TERM', '--'] + command
        log = open(self.log_path, 'ab')
        try:
            self.process = subprocess.Popen(
                command, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                env=self.env, start_new_session=True)
        finally:
            log.close()
        return self

    @property
    def pid(self):
        """Return the process id (None before start)."""
        return None if self.process is None else self.process.pid

    def alive(self):
        """Return whether the process runs."""
        return self.process is not None and self.process.poll() is None

    def returncode(self):
        """Return the exit status (None while running)."""
        return None if self.process is None else self.process.poll()

    def tail(self, lines=20):
        """Return the last `lines` lines of the log."""
        try:
            with open(self.log_path, errors='replace') as stream:
                return ''.join(collections.deque(stream, maxlen=lines))
        except OSError:
            return ''

    def signal(self, signum):
        """Send `signum` to the node's process group (the node and anything it started)."""
        if self.alive():
            try:
                os.killpg(self.process.pid, signum)
            except ProcessLookupError:
                pass

    def stop(self, interrupt_timeout=10.0, terminate_timeout=5.0):
        """
        Stop the node: SIGINT (Ctrl-C), then SIGTERM, then SIGKILL after the timeouts [s].

        Return the signal that ended it (``'SIGINT'``, ``'SIGTERM'``, ``'SIGKILL'``) or
        ``'exited'`` when it had already stopped.
        """
        if not self.alive():
            return 'exited'
        for signum, timeout in ((signal.SIGINT, interrupt_timeout),
                                (signal.SIGTERM, terminate_timeout), (signal.SIGKILL, 5.0)):
            self.signal(signum)
            try:
                self.process.wait(timeout)
                return signal.Signals(signum).name
            except subprocess.TimeoutExpired:
                continue
        raise NodeProcessError(f'{self.label} (pid {self.pid}) survived SIGKILL')


class ProcessGroup:
    """
    Several NodeProcesses started together and stopped together.

    A watcher thread notices a process that ends while the group runs and calls
    `on_death(process)` (default: remember it; ``check()`` raises NodeProcessError naming it
    with its last log lines).
    """

    def __init__(self, processes, on_death=None, poll_period=0.1, stop_first=()):
        """
        Keep `processes` (NodeProcess) to start in order and stop in reverse order.

        `stop_first`: labels of processes stopped one after the other, each awaited, before
        the others are signalled (those that must act on the way out while the rest of the
        graph still runs: the painter, then the lens planner, which retreat the lens).
        """
        self.processes = list(processes)
        self.stop_first = tuple(stop_first)
        self.deaths = []
        self._on_death = on_death
        self._stopping = threading.Event()
        self._poll_period = poll_period
        self._watcher = None

    def start(self):
        """Start every process and the watcher; return self."""
        try:
            for process in self.processes:
                process.start()
        except BaseException:
            self.stop()
            raise
        self._watcher = threading.Thread(target=self._watch, daemon=True, name='node-watcher')
        self._watcher.start()
        return self

    def _watch(self):
        reported = set()
        while not self._stopping.wait(self._poll_period):
            for process in self.processes:
                if process.process is None or process.label in reported or process.alive():
                    continue
                reported.add(process.label)
                self.deaths.append(process)
                if self._on_death is not None:
                    self._on_death(process)

    def check(self):
        """Raise NodeProcessError if a process died, naming it with its last log lines."""
        if self.deaths:
            dead = self.deaths[0]
            raise NodeProcessError(f'{dead.label} exited with status {dead.returncode()}; '
                                   f'last log lines:\n{dead.tail()}')

    def stop(self, interrupt_timeout=10.0, terminate_timeout=5.0):
        """
        Stop every process; return how each ended.

        First the `stop_first` ones in their order, each given SIGINT and awaited (then
        SIGTERM and SIGKILL after the timeouts); then the others, SIGINT together, awaited in
        reverse order.
        """
        self._stopping.set()
        outcomes = {}
        for label in self.stop_first:
            for process in self.processes:
                if process.label == label and process.process is not None:
                    outcomes[label] = process.stop(interrupt_timeout, terminate_timeout)
        rest = [p for p in self.processes if p.label not in outcomes]
        for process in rest:
            process.signal(signal.SIGINT)
        deadline = time.monotonic() + interrupt_timeout
        for process in reversed(rest):
            if process.process is None:
                continue
            try:
                process.process.wait(max(0.0, deadline - time.monotonic()))
                outcomes[process.label] = 'SIGINT' if process.returncode() is not None else '?'
            except subprocess.TimeoutExpired:
                outcomes[process.label] = process.stop(0.0, terminate_timeout)
        if self._watcher is not None:
            self._watcher.join(timeout=5.0)
        return outcomes

    def __enter__(self):
        """Start the group."""
        return self.start()

    def __exit__(self, *exc):
        """Stop the group."""
        self.stop()
