"""
The run journal: what a painting did, one JSON object per line, written as it happens.

``runs/<UTC time>/journal.jsonl`` is written by the painter and read by the run report
(``helio_control.report``). Lines, in order:

1. ``{"kind": "run", "goal": {...}, "started": <sim s>, "wall_started": <unix s>,
   "dot_calibration_s": <s>}``: the PaintPattern goal's fields (``goal_to_dict``), when the
   run began and how long of it the dot-size test row took (0 or absent: none);
2. one ``{"kind": "dot", "index", "target": [x, y], "n_p_target", "start", "end", "dwell",
   "peak_n_p", "t_max", "outcome", "reason", "restarts"}`` per dot as it finishes (times in
   simulated or ROS seconds, ``dwell`` the heating time [s], ``t_max`` [degC], ``target``
   world [m], ``outcome`` one of ``burnt``, ``skipped``, ``failed``, ``restarts`` the
   heatings broken off and begun again: a stale thermal stream, a cloud; 0 when absent;
   ``verdict`` the RGB camera's after the dot: ``charred``, ``not charred`` or ``''`` (not
   verified), ``verdict_reason`` why not, ``measured_diameter`` the char's equivalent
   diameter it measured [m] (0 without char), ``reheats`` the heatings again of a dot the
   camera found not charred, ``hold`` how long [s] the dot was to be held at its N_p
   target once reached (a dot wider than N_p can ask for), ``cooling`` the retreat's wait
   for N_p = 0 [s]; absent in older journals);
3. ``{"kind": "result", "success", "dots_burnt", "dots_skipped", "duration",
   "wall_duration", "message"}`` at the end.

Every line is flushed when written, so a run that crashes keeps every finished dot; a
reader accepts a last line cut off by a crash (``Journal.truncated``) and refuses anything
else malformed with the line number.

Resume: a run directory also holds ``plan.json`` (the run's ``helio_control.plan.Plan``) and
``resume.json`` (``{"goal_key", "burnt_before", "resumed_from"}``, ``start_run``). The same
goal sent again (``goal_key``: its fields but ``NOT_THE_PICTURE``, and the picture's content)
continues the newest unfinished run of it (``unfinished_run``) with that run's plan: the
dots burnt there and in the runs it resumed are skipped, and ``dots_left`` are painted, none
lost and none doubled. Pure Python: no rclpy.
"""

from dataclasses import asdict, dataclass, field, fields, MISSING
import glob
import hashlib
import json
import math
import os

OUTCOMES = ('burnt', 'skipped', 'failed')
VERDICTS = ('charred', 'not charred', '')
# Goal fields that do not change what is painted (a resumed goal may differ in them).
NOT_THE_PICTURE = ('run_dir', 'fresh', 'start_index', 'dry_run')


class JournalError(ValueError):
    """A journal line that is not what the format says."""


def _number(record, name, value, integer=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise JournalError(f'{record}: {name} must be a number, not {value!r}')
    if integer and (not float(value).is_integer() or value < 0):
        raise JournalError(f'{record}: {name} must be a count (integer >= 0), not {value!r}')
    if not math.isfinite(value):
        raise JournalError(f'{record}: {name} must be finite, not {value!r}')
    return int(value) if integer else float(value)


@dataclass
class RunRecord:
    """The first line: the goal and when the run started."""

    goal: dict
    started: float              # [s] on the graph's clock (simulated in the simulated world)
    wall_started: float         # [s] unix time
    dot_calibration_s: float = 0.0   # [s] of it the dot-size test row took, before the plan
    kind: str = field(default='run', init=False)

    def validate(self):
        """Return self after checking the fields (JournalError otherwise)."""
        if not isinstance(self.goal, dict):
            raise JournalError(f'run: goal must be an object, not {self.goal!r}')
        self.started = _number('run', 'started', self.started)
        self.wall_started = _number('run', 'wall_started', self.wall_started)
        self.dot_calibration_s = _number('run', 'dot_calibration_s', self.dot_calibration_s)
        return self


@dataclass
class DotRecord:
    """One dot as it finished."""

    index: int
    target: list                # world [x, y] [m]
    n_p_target: int
    start: float                # [s] when the move to the dot began
    end: float                  # [s] when N_p was back to 0 (or the dot was given up)
    dwell: float                # [s] heating time
    peak_n_p: int
    t_max: float                # [degC] highest T_max while heating
    outcome: str                # 'burnt', 'skipped' or 'failed'
    reason: str = ''
    restarts: int = 0           # heatings broken off and begun again (stale stream, cloud)
    verdict: str = ''           # the RGB camera's: 'charred', 'not charred', '' (not verified)
    verdict_reason: str = ''    # why not charred, or why not verified
    measured_diameter: float = 0.0   # the char the camera measured at the target [m]
    reheats: int = 0            # heatings again of a dot the camera found not charred
    hold: float = 0.0           # [s] held at N_p >= n_p_target once reached (dot_cycle)
    cooling: float = 0.0        # [s] the retreat's wait for N_p = 0 (0: none or not waited)
    kind: str = field(default='dot', init=False)

    def validate(self):
        """Return self after checking the fields (JournalError otherwise)."""
        record = f'dot {self.index}'
        self.index = _number(record, 'index', self.index, integer=True)
        if not isinstance(self.target, (list, tuple)) or len(self.target) != 2:
            raise JournalError(f'{record}: target must be [x, y] in metres, not {self.target!r}')
        self.target = [_number(record, 'target', value) for value in self.target]
        self.n_p_target = _number(record, 'n_p_target', self.n_p_target, integer=True)
        self.peak_n_p = _number(record, 'peak_n_p', self.peak_n_p, integer=True)
        self.restarts = _number(record, 'restarts', self.restarts, integer=True)
        self.reheats = _number(record, 'reheats', self.reheats, integer=True)
        if self.verdict not in VERDICTS:
            raise JournalError(f'{record}: verdict must be one of {VERDICTS}, not '
                               f'{self.verdict!r}')
        for name in ('start', 'end', 'dwell', 't_max', 'measured_diameter', 'hold',
                     'cooling'):
            setattr(self, name, _number(record, name, getattr(self, name)))
        if self.outcome not in OUTCOMES:
            raise JournalError(f'{record}: outcome must be one of {OUTCOMES}, not '
                               f'{self.outcome!r}')
        if not isinstance(self.reason, str):
            raise JournalError(f'{record}: reason must be a string')
        return self


@dataclass
class ResultRecord:
    """The last line: the action's result and the run's wall time."""

    success: bool
    dots_burnt: int
    dots_skipped: int
    duration: float             # [s] on the graph's clock
    wall_duration: float        # [s]
    message: str = ''
    kind: str = field(default='result', init=False)

    def validate(self):
        """Return self after checking the fields (JournalError otherwise)."""
        if not isinstance(self.success, bool):
            raise JournalError(f'result: success must be true or false, not {self.success!r}')
        self.dots_burnt = _number('result', 'dots_burnt', self.dots_burnt, integer=True)
        self.dots_skipped = _number('result', 'dots_skipped', self.dots_skipped, integer=True)
        self.duration = _number('result', 'duration', self.duration)
        self.wall_duration = _number('result', 'wall_duration', self.wall_duration)
        if not isinstance(self.message, str):
            raise JournalError('result: message must be a string')
        return self


RECORDS = {'run': RunRecord, 'dot': DotRecord, 'result': ResultRecord}


def record_from_dict(data):
    """Return the record a journal object describes (JournalError when it is not one)."""
    if not isinstance(data, dict):
        raise JournalError(f'a journal line must be a JSON object, not {data!r}')
    kind = data.get('kind')
    if kind not in RECORDS:
        raise JournalError(f'unknown kind {kind!r} (expected one of {sorted(RECORDS)})')
    record_type = RECORDS[kind]
    names = {f.name for f in fields(record_type) if f.init}
    required = {f.name for f in fields(record_type)
                if f.init and f.default is MISSING and f.default_factory is MISSING}
    missing = required - set(data)
    if missing:
        raise JournalError(f'{kind} line misses {sorted(missing)}')
    return record_type(**{name: data[name] for name in names if name in data}).validate()


def goal_to_dict(goal):
    """
    Return a PaintPattern goal (any ROS message) as plain JSON values.

    Nested messages become objects and sequences lists; the bulk data of an image (its
    ``data`` bytes) is replaced by its length, so the journal names the picture without
    holding it.
    """
    if hasattr(goal, 'get_fields_and_field_types'):
        result = {}
        for name in goal.get_fields_and_field_types():
            value = getattr(goal, name)
            if name == 'data' and hasattr(goal, 'encoding'):
                result['data_bytes'] = len(value)
                continue
            result[name] = goal_to_dict(value)
        return result
    if isinstance(goal, (bytes, bytearray)):
        return len(goal)
    if isinstance(goal, str) or goal is None or isinstance(goal, (bool, int, float)):
        return goal
    if hasattr(goal, 'tolist'):
        return goal.tolist()
    try:
        return [goal_to_dict(item) for item in goal]
    except TypeError:
        return str(goal)


class JournalWriter:
    """Append records to a journal, one line each, flushed to the OS as written."""

    def __init__(self, path):
        """Open `path` for appending (its directory is made)."""
        directory = os.path.dirname(os.path.abspath(path))
        os.makedirs(directory, exist_ok=True)
        self.path = path
        self._stream = open(path, 'a', encoding='utf-8')

    def write(self, record):
        """Validate and append one record; return it."""
        record.validate()
        self._stream.write(json.dumps(asdict(record), allow_nan=False) + '\n')
        self._stream.flush()
        return record

    def run(self, goal, started, wall_started, dot_calibration_s=0.0):
        """Append the run line (`goal`: a message or a dict)."""
        goal = goal if isinstance(goal, dict) else goal_to_dict(goal)
        return self.write(RunRecord(goal, started, wall_started, float(dot_calibration_s)))

    def dot(self, **values):
        """Append one dot line (the DotRecord fields)."""
        return self.write(DotRecord(**values))

    def result(self, **values):
        """Append the result line (the ResultRecord fields)."""
        return self.write(ResultRecord(**values))

    def close(self):
        """Close the file."""
        self._stream.close()

    def __enter__(self):
        """Return self."""
        return self

    def __exit__(self, *exc):
        """Close the file."""
        self.close()


@dataclass
class Journal:
    """A journal as read: the run, the dots in order, the result (None when missing)."""

    run: RunRecord = None
    dots: list = field(default_factory=list)
    result: ResultRecord = None
    truncated: bool = False     # the last line was cut off (the writer died mid-line)


def read_journal(path):
    """
    Read a journal file; return a Journal.

    JournalError (with the line number) for a malformed line, a second run or result line,
    or dots before the run line. Only the last line may be cut off: that is what a crash
    leaves.
    """
    journal = Journal()
    with open(path, encoding='utf-8') as stream:
        lines = stream.read().split('\n')
    complete = lines[:-1]           # a complete line ends with '\n'
    if lines[-1].strip():
        journal.truncated = True
    for number, line in enumerate(complete, 1):
        if not line.strip():
            continue
        try:
            data = json.loads(line)
        except json.JSONDecodeError as error:
            raise JournalError(f'{path}:{number}: not JSON ({error.msg})') from None
        try:
            record = record_from_dict(data)
        except (JournalError, TypeError) as error:
            raise JournalError(f'{path}:{number}: {error}') from None
        if isinstance(record, RunRecord):
            if journal.run is not None:
                raise JournalError(f'{path}:{number}: a second run line')
            journal.run = record
        elif journal.run is None:
            raise JournalError(f'{path}:{number}: {record.kind} line before the run line')
        elif journal.result is not None:
            raise JournalError(f'{path}:{number}: {record.kind} line after the result line')
        elif isinstance(record, DotRecord):
            journal.dots.append(record)
        else:
            journal.result = record
    return journal


def goal_key(goal):
    """
    Return a key naming what a goal paints.

    The goal's fields but NOT_THE_PICTURE, and the picture's content (an edited file is a
    new painting).
    """
    painted = {k: v for k, v in goal_to_dict(goal).items() if k not in NOT_THE_PICTURE}
    if goal.image_path and os.path.isfile(goal.image_path):
        with open(goal.image_path, 'rb') as stream:
            painted['image_sha256'] = hashlib.sha256(stream.read()).hexdigest()
    if goal.image.width:
        painted['image_sha256'] = hashlib.sha256(bytes(goal.image.data)).hexdigest()
    return hashlib.sha256(json.dumps(painted, sort_keys=True).encode()).hexdigest()[:16]


def unfinished_run(runs_dir, key):
    """
    Return (run dir, burnt indices) of the newest unfinished run of the goal `key`, or None.

    A run is unfinished when its journal has no result line or an unsuccessful one. The
    burnt dots are those of its journal and of the runs it resumed (``resume.json``).
    """
    candidates = []
    for resume in glob.glob(os.path.join(runs_dir, '*', 'resume.json')):
        try:
            with open(resume) as stream:
                state = json.load(stream)
        except (OSError, ValueError):
            continue
        if state.get('goal_key') == key:
            candidates.append((os.path.getmtime(resume), os.path.dirname(resume), state))
    for _, run_dir, state in sorted(candidates, reverse=True):
        journal_path = os.path.join(run_dir, 'journal.jsonl')
        try:
            journal = read_journal(journal_path)
        except (OSError, JournalError):
            continue
        if journal.result is not None and journal.result.success:
            return None              # the newest run of this goal finished: start over
        burnt = set(state.get('burnt_before', []))
        burnt.update(dot.index for dot in journal.dots if dot.outcome == 'burnt')
        return run_dir, burnt
    return None


def dots_left(count, burnt, start_index=0):
    """Return the indices of a plan's `count` dots to paint: not `burnt`, from `start_index`."""
    return [i for i in range(count) if i not in burnt and i >= start_index]


def start_run(run_dir, plan_json, key, burnt, resumed_from=''):
    """
    Write a run's ``plan.json`` and ``resume.json`` in `run_dir` (made); return its journal.

    `burnt`: the dots burnt by the runs it resumes, the newest of them `resumed_from`. The
    JournalWriter appends to ``journal.jsonl``.
    """
    os.makedirs(run_dir, exist_ok=True)
    with open(os.path.join(run_dir, 'plan.json'), 'w') as stream:
        stream.write(plan_json)
    with open(os.path.join(run_dir, 'resume.json'), 'w') as stream:
        json.dump({'goal_key': key, 'burnt_before': sorted(burnt),
                   'resumed_from': resumed_from}, stream)
    return JournalWriter(os.path.join(run_dir, 'journal.jsonl'))
