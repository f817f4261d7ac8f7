"""
The rig doctor's checklist (issue 30, item 6): facts about a running graph in, findings out.

``helio doctor`` gathers facts from the graph for a few seconds
(``helio_control.doctor_probe``: latched device statuses, message counts and stamps of each
camera, camera_info matrices, thermal statistics, spot observations, ``/clock``, the nodes'
``site_file`` and ``calibration_dir`` parameters) and hands them to the checks here. Each
check is a plain function of those facts (no rclpy) and returns ``Finding`` lines: a name,
``OK``/``WARN``/``FAIL``, what was found and, unless OK, how to fix it. Nothing here or in
the probe moves the rig.

FAIL is what stops a painting or makes it unsafe or wrong (a device not connected, an
alarm, a camera silent or uncalibrated, a thermal read-out that cannot reach the pyrolysis
threshold, the sample site, a clock before the build, a calibration made for another rig,
the emergency stop engaged); WARN is what a person should know but the graph copes with
(homing not observable, the marker not in view at the arm's current pose, no calibration
saved yet: the painter calibrates robot-world itself, a time zone far from the site's).
"""

from dataclasses import asdict, dataclass, field
import datetime
import math
import os

from helio_optics.node_kit import topics
from helio_optics.thermal_cameras import PAPER

OK, WARN, FAIL = 'OK', 'WARN', 'FAIL'
LEVELS = (OK, WARN, FAIL)
# The calibrations the lens planner reads back at start (calibration_store, issue 30 item 4)
EXPECTED_CALIBRATIONS = ('robot_world.yaml', 'focus.yaml')
CALIBRATION_FIXES = {
    'robot_world.yaml': 'the painter measures it at its first painting (calibrate_world: '
                        'once); or send the lens planner a calibrate_world goal with apply',
    'focus.yaml': 'send the lens planner a calibrate_focus goal with apply in sunshine (the '
                  'heating distance is the lens_planner default until then)',
}
DOBOT_ALARM_FIX = ('remove the cause (move a joint back inside its limits by hand, free the '
                   'arm, check its power), then: ros2 service call /dobot/clear_alarms '
                   'std_srvs/srv/Trigger')
SERVO_ALARM_FIX = ("check the servos' power and wiring and the Maestro's settings (Maestro "
                   'Control Center, serial mode USB Dual Port); the servo driver reads and '
                   'clears its error bits')
HOME_FIX = ('home the arm once after power-on: ros2 service call /dobot/home '
            'std_srvs/srv/Trigger (or run dobot_driver with home_on_connect: true)')


@dataclass
class Settings:
    """What the checks expect: camera rates and the tolerances around them."""

    rgb_rate: float = 5.0              # [Hz] sim_world's rgb_rate; a webcam gives 15-30
    thermal_rate: float = 8.7          # [Hz] sim_world's thermal_rate; a Lepton < 9
    rate_tolerance: float = 0.7        # measured rate below this share of expected: FAIL
    thermal_floor: float = -40.0       # [degC] a reading below this is a wrong calibration
    pyrolysis: float = PAPER.cap       # [degC] the paper's T_p (its camera's cap)
    timezone_tolerance: float = 3.0    # [h] local offset from longitude/15 before a WARN
    stamp_tolerance: float = 2.0       # [s] images and joint states stamped further apart fail

    def expected_rate(self, kind):
        """Return the expected image rate of camera `kind` (rgb or thermal) [Hz]."""
        return {'rgb': self.rgb_rate, 'thermal': self.thermal_rate}[kind]


@dataclass
class Finding:
    """One line of the checklist."""

    name: str
    level: str
    finding: str
    fix: str = ''

    def line(self):
        """Return the line a person reads: level, name, finding and the fix."""
        text = f'{self.level:<4} {self.name}: {self.finding}'
        return text + (f'\n       fix: {self.fix}' if self.fix and self.level != OK else '')


@dataclass
class DeviceFacts:
    """A driver's latched DeviceStatus (None of these: no status heard)."""

    connected: bool
    alarms: list = field(default_factory=list)
    message: str = ''
    port: str = ''


@dataclass
class StreamFacts:
    """Messages of one topic in the window: header stamps [s] and wall arrival times [s]."""

    topic: str
    stamps: list = field(default_factory=list)
    arrivals: list = field(default_factory=list)

    @property
    def count(self):
        """Return how many messages arrived."""
        return len(self.arrivals)

    @property
    def frames(self):
        """Return how many distinct stamps arrived: a frame sent again counts once."""
        return len(set(self.stamps))

    def stamp_rate(self):
        """Return the frame rate by the stamps (the camera's own clock) [Hz], NaN below 2."""
        if self.frames < 2:
            return math.nan
        span = max(self.stamps) - min(self.stamps)
        return (self.frames - 1) / span if span > 0.0 else math.nan

    def wall_rate(self):
        """Return the frames' arrival rate on the wall clock [Hz], NaN below 2 frames."""
        if self.frames < 2:
            return math.nan
        span = self.arrivals[-1] - self.arrivals[0]
        return (self.frames - 1) / span if span > 0.0 else math.nan


@dataclass
class ThermalFacts:
    """One thermal/stats message: what the monitor read and the range it works with."""

    t_max: float
    threshold: float
    camera_cap: float
    saturated: bool = False


@dataclass
class SpotFacts:
    """One spot observation: where its camera pose came from, and why it is not valid."""

    camera_pose_source: str
    reason: str = ''
    valid: bool = False


@dataclass
class ClockFacts:
    """``/clock`` samples (wall [s], sim [s]) and the machine's clock and time zone."""

    samples: list = field(default_factory=list)
    now: datetime.datetime = None                 # aware, UTC
    utc_offset: float = 0.0                       # local time zone's offset [s]
    not_before: datetime.datetime = None          # the build's date: the clock is after it
    ntp_synchronized: bool = None                 # None: not known


@dataclass
class CalibrationFacts:
    """The calibration directory, where that came from, and what it holds for this rig."""

    directory: str
    source: str
    description: str
    rig_file: str
    entries: list = field(default_factory=list)   # calibration_store.list_calibrations


@dataclass
class Facts:
    """Everything the checks look at; None where nothing was heard or asked."""

    window: float = 0.0
    devices: dict = field(default_factory=dict)          # 'dobot'/'servo' -> DeviceFacts
    home_on_connect: bool = None                         # dobot_driver's parameter
    images: dict = field(default_factory=dict)           # 'rgb'/'thermal' -> StreamFacts
    joint_states: StreamFacts = None                     # the drivers' joint_states
    camera_infos: dict = field(default_factory=dict)     # kind -> [K (9 floats)]
    thermal: list = field(default_factory=list)          # ThermalFacts
    spots: list = field(default_factory=list)            # SpotFacts
    site_files: dict = field(default_factory=dict)       # where from -> path
    sample_site: str = ''                                # the shipped config/site.yaml
    clock: ClockFacts = None
    calibration: CalibrationFacts = None
    emergency_stop: bool = None
    namespace: str = ''
    domain: str = ''
    discovery: float = 0.0                               # [s] before the window started


# ---------------------------------------------------------------------------- devices
def check_device(device, status, namespace=''):
    """Return the finding of a driver's link: connected, or why not."""
    name = f'{device} connected'
    topic = _topic(namespace, topics.device_status(device))
    if status is None:
        return Finding(name, FAIL, f'no {topic} heard (is {device}_driver running in this '
                       'ROS_DOMAIN_ID and namespace?)',
                       'start the graph: helio rig --dobot-port ... --servo-port ... (or '
                       'check ROS_DOMAIN_ID and --namespace)')
    if not status.connected:
        return Finding(name, FAIL, f'{device} not connected on {status.port or "?"}: '
                       f'{status.message or "no message"}',
                       'plug in and power the device, check the port (ls /dev/serial/by-id/) '
                       'and its permissions (helio udev; the dialout group); the driver '
                       'reconnects by itself')
    return Finding(name, OK, f'{device} connected on {status.port}')


def check_alarms(device, status):
    """Return the finding of a device's active alarms (FAIL with the fix when any)."""
    name = f'{device} alarms'
    if status is None:
        return Finding(name, WARN, f'no {device}/status: alarms unknown',
                       f'start {device}_driver')
    if status.alarms:
        return Finding(name, FAIL, f'{len(status.alarms)} active: ' + '; '.join(status.alarms),
                       DOBOT_ALARM_FIX if device == 'dobot' else SERVO_ALARM_FIX)
    return Finding(name, OK, 'none active')


def check_homing(status, home_on_connect):
    """
    Return the finding of the Dobot's homing.

    The Dobot does not report whether it was homed since power-on; the driver homes on
    connect when ``home_on_connect`` is set, and says so in its status after a home.
    """
    name = 'dobot homed'
    if status is not None and 'homed' in status.message:
        return Finding(name, OK, f'dobot/status says: {status.message}')
    if home_on_connect:
        return Finding(name, OK, 'dobot_driver homes the arm on connect (home_on_connect)')
    known = '' if home_on_connect is not None else ' (dobot_driver parameters not answered)'
    return Finding(name, WARN, 'not observable: the Dobot does not report whether it was homed '
                   f'since power-on, and dobot_driver does not home on connect{known}',
                   HOME_FIX)


# ---------------------------------------------------------------------------- cameras
def check_camera_rate(kind, stream, expected, tolerance, window):
    """Return the finding of a camera's image rate against `expected` [Hz]."""
    name = f'{kind} camera rate'
    topic = stream.topic if stream is not None else f'{kind}/image_raw'
    fix = (f'check the {kind} camera: plugged in, its driver running (helio rig '
           f'--{kind}-camera PKG/EXE), publishing {topic}; its frame rate setting')
    if stream is None or stream.count == 0:
        return Finding(name, FAIL, f'no image on {topic} in {window:.1f} s', fix)
    rate = stream.stamp_rate()
    wall = stream.wall_rate()
    again = stream.count - stream.frames
    measured = (f'{stream.frames} frames ({again} sent again), {rate:.2f} Hz by their stamps, '
                f'{wall:.2f} Hz arriving')
    if not math.isfinite(rate) or rate < tolerance * expected:
        return Finding(name, FAIL, f'{measured}; expected {expected:g} Hz (at least '
                       f'{tolerance * expected:.2f})', fix + ' (or give doctor the rate you '
                       f'expect: --{kind}-rate)')
    return Finding(name, OK, f'{measured} (expected {expected:g} Hz)')


def intrinsics_problem(k):
    """Return why a CameraInfo K (9 floats) is not a calibration ('' when it is one)."""
    if len(k) != 9:
        return f'K has {len(k)} values, not 9'
    if not all(math.isfinite(v) for v in k):
        return 'K is not finite'
    if all(v == 0.0 for v in k):
        return 'K is all zero (an uncalibrated camera: usb_cam sends it without a calibration)'
    if k[0] <= 0.0 or k[4] <= 0.0 or k[8] != 1.0:
        return f'K is not an intrinsic matrix (fx {k[0]:g}, fy {k[4]:g}, K[8] {k[8]:g})'
    return ''


def check_camera_info(kind, matrices, window):
    """Return the finding of a camera's camera_info: every K heard is a calibration."""
    name = f'{kind} camera_info calibrated'
    if kind == 'rgb':      # the rig calibrates it over a printed board (issue 29, item 5)
        fix = ('helio calibrate camera (the rig moves the camera over a ChArUco board printed '
               'with helio print board), then give its driver the file (usb_cam: '
               'camera_info_url), or restart spot_detector: it reads the file from its '
               'calibration_dir while the camera_info is uncalibrated')
    else:
        fix = (f'calibrate the {kind} camera (ros2 run camera_calibration cameracalibrator, a '
               'checkerboard) and give its driver the result (usb_cam: camera_info_url)')
    if not matrices:
        return Finding(name, FAIL, f'no {kind}/camera_info in {window:.1f} s', fix)
    problems = [intrinsics_problem(list(k)) for k in matrices]
    bad = [p for p in problems if p]
    if bad:
        return Finding(name, FAIL, f'{len(bad)} of {len(matrices)} camera_info messages are '
                       f'not calibrated: {bad[-1]}', fix)
    k = list(matrices[-1])
    return Finding(name, OK, f'fx {k[0]:.1f} px, fy {k[4]:.1f} px, centre ({k[2]:.1f}, '
                   f'{k[5]:.1f}) px')


def check_thermal_range(stats, settings, window):
    """
    Return the finding of the thermal read-out: it can reach the pyrolysis threshold.

    The thermal monitor counts N_p (pixels at or above its threshold T_p); a monitor whose
    threshold lies above the camera's cap never counts a charring dot. Since issue 29 the
    monitor counts from the cap when the camera reads less than T_p (a Lepton in high gain
    tops out at 140 degC): its saturated pixels, which a dot-size calibration must relate to
    the dots (a warning). A reading below ``thermal_floor`` means a wrong radiometric
    conversion.
    """
    name = 'thermal range for charring'
    if not stats:
        return Finding(name, FAIL, f'no thermal/stats in {window:.1f} s (no thermal stream, or '
                       'thermal_monitor not running)',
                       'start thermal_monitor and check the thermal camera (see its rate)')
    last = stats[-1]
    if last.camera_cap < last.threshold:
        return Finding(name, FAIL, f'the read-out stops at {last.camera_cap:g} degC, below the '
                       f'pyrolysis threshold {last.threshold:g} degC: N_p stays 0',
                       'put the camera in its high-temperature range (a Lepton: low gain, to '
                       'about 400 degC) and set thermal_monitor camera_cap to its read-out '
                       'cap, or lower threshold to what it can read')
    coldest = min(s.t_max for s in stats)
    hottest = max(s.t_max for s in stats)
    if coldest < settings.thermal_floor or hottest > last.camera_cap + 1.0:
        return Finding(name, FAIL, f'readings {coldest:.1f}..{hottest:.1f} degC are not a '
                       f'scene (read-out cap {last.camera_cap:g} degC)',
                       'check the radiometric conversion: thermal_monitor mono16.gain/offset '
                       '(a Lepton in TLinear: 0.01 K per count, offset -273.15) and the '
                       "camera's gain mode")
    if last.camera_cap < settings.pyrolysis:
        return Finding(name, WARN, f'the read-out stops at {last.camera_cap:g} degC, below the '
                       f"paper's pyrolysis threshold {settings.pyrolysis:g} degC: N_p counts the "
                       'saturated pixels, and the dot an N_p target burns differs from the '
                       "paper's", "for dots of the paper's size, a camera mode reading past "
                       f'{settings.pyrolysis:g} degC (a Lepton: low gain, thermal_monitor '
                       'camera_profile lepton35_low_gain); else check the dot size with a test '
                       'row')
    return Finding(name, OK, f'read-out up to {last.camera_cap:g} degC reaches the pyrolysis '
                   f'threshold {last.threshold:g} degC; T_max now {last.t_max:.1f} degC')


def check_marker(spots, window):
    """Return the finding of the marker: seen by the RGB camera in the window's images."""
    name = 'marker visible'
    if not spots:
        return Finding(name, FAIL, f'no spot observation in {window:.1f} s (spot_detector not '
                       'running, or no RGB images)',
                       'start spot_detector and check the RGB camera (see its rate)')
    seen = sum(1 for spot in spots if spot.camera_pose_source == 'marker')
    if seen == 0:
        poses = {'kinematics': "camera pose from the joints' kinematics",
                 '': 'no camera pose'}
        used = sorted({poses.get(spot.camera_pose_source, spot.camera_pose_source)
                       for spot in spots})
        reasons = sorted({spot.reason for spot in spots if spot.reason})[:2]
        return Finding(name, WARN, f'the marker is in none of {len(spots)} RGB images at the '
                       f"arm's pose now ({', '.join(used)}; spot_detector says: "
                       f"{'; '.join(reasons) or 'nothing'})",
                       'move the arm so the RGB camera looks at the marker, and check it: '
                       'printed at marker_side (measure it), flat, lit, not covered, the '
                       'marker_id and dictionary of spot_detector')
    return Finding(name, OK, f'seen in {seen} of {len(spots)} RGB images')


# ---------------------------------------------------------------------------- files
def site_coordinates(path):
    """Return (latitude_deg, longitude_deg) of a site file."""
    from helio_optics.ephemeris import load_site
    site = load_site(path)
    return site.latitude_deg, site.longitude_deg


def check_site(site_files, sample, coordinates=site_coordinates):
    """
    Return the finding of the site files: none is the shipped sample's.

    `site_files` maps where each came from (``--site``, ``sun_estimator.site_file``) to its
    path; a file is the sample's when it is the sample or has its latitude and longitude.
    """
    name = 'site file'
    fix = ('copy config/site.yaml, put your latitude, longitude and elevation in it (a '
           "phone's GPS is close enough) and give it to the graph: helio rig --set "
           'sun_estimator.site_file=PATH --set lens_planner.site_file=PATH --set '
           'painter.site_file=PATH')
    if not site_files:
        return Finding(name, WARN, 'no site_file known (the nodes did not answer)',
                       'give doctor the site file: --site FILE')
    try:
        sample_at = coordinates(sample)
    except (OSError, ValueError, KeyError) as error:
        return Finding(name, WARN, f'the sample {sample} cannot be read: {error}', fix)
    samples, read = [], []
    for source, path in sorted(site_files.items()):
        try:
            at = coordinates(path)
        except (OSError, ValueError, KeyError) as error:
            return Finding(name, FAIL, f'{source}: {path} cannot be read: {error}', fix)
        same_file = os.path.realpath(path) == os.path.realpath(sample)
        if same_file or all(math.isclose(a, b, abs_tol=1e-6) for a, b in zip(at, sample_at)):
            samples.append(f'{source} = {path}')
        read.append(f'{source} = {path} ({at[0]:.4f}, {at[1]:.4f})')
    if samples:
        return Finding(name, FAIL, f'the shipped sample site ({sample_at[0]:.3f} N, '
                       f"{sample_at[1]:.3f} E, the simulated world's): " + '; '.join(samples),
                       fix)
    return Finding(name, OK, '; '.join(read))


def check_clock(clock, site_longitude=None, settings=None):
    """
    Return the findings of the clocks: /clock advancing, the system clock after the build.

    With ``/clock`` samples (a simulated graph) the simulated time must advance. The
    machine's clock must be after the build's date (a Raspberry Pi without network starts
    in the past), NTP synchronised when that is known, and its time zone near the site's
    longitude/15 h (helio works in UTC; a zone far off usually means a clock set by hand).
    """
    settings = settings or Settings()
    findings = []
    if clock.samples:
        (wall0, sim0), (wall1, sim1) = clock.samples[0], clock.samples[-1]
        if sim1 > sim0:
            pace = (sim1 - sim0) / (wall1 - wall0) if wall1 > wall0 else math.inf
            findings.append(Finding('simulated clock', OK, f'/clock advancing ({pace:.2f} s '
                                    'simulated per wall second)'))
        else:
            findings.append(Finding('simulated clock', FAIL, f'/clock stands at {sim1:.2f} s',
                                    'sim_world is stalled or paused: check its log and its '
                                    'real_time_factor'))
    name = 'system clock'
    if clock.now is None:
        return findings
    if clock.not_before is not None and clock.now < clock.not_before:
        findings.append(Finding(name, FAIL, f'the clock says {clock.now.isoformat()}, before '
                                f'this build ({clock.not_before.date().isoformat()})',
                                'set the clock: timedatectl set-ntp true (with a network) or '
                                'sudo date -s ...; the sun ephemeris needs the true time'))
    elif clock.ntp_synchronized is False:
        findings.append(Finding(name, WARN, f'{clock.now.isoformat(timespec="seconds")}, not '
                                'NTP synchronised', 'timedatectl set-ntp true (needs a '
                                'network); the sun moves 0.25 deg per minute'))
    else:
        findings.append(Finding(name, OK, f'{clock.now.isoformat(timespec="seconds")}'
                                + (', NTP synchronised' if clock.ntp_synchronized else '')))
    offset_h = clock.utc_offset / 3600.0
    if site_longitude is not None:
        solar = site_longitude / 15.0
        if abs(offset_h - solar) > settings.timezone_tolerance:
            findings.append(Finding('time zone', WARN, f'UTC{offset_h:+g} h, at a site whose '
                                    f'longitude {site_longitude:.2f} deg suggests about '
                                    f'UTC{solar:+.0f} h', 'sudo timedatectl set-timezone '
                                    'Region/City (helio works in UTC, but a wrong zone often '
                                    'means a clock set by hand)'))
        else:
            findings.append(Finding('time zone', OK, f'UTC{offset_h:+g} h for longitude '
                                    f'{site_longitude:.2f} deg'))
    return findings


def check_time_base(images, joints, tolerance):
    """
    Return the finding of the stamps: camera images and joint states on one clock.

    The spot detector and the thermal monitor look up the arm's joints at each image's
    stamp (within 0.3 s): images stamped on another clock than the drivers' joint states
    (a simulated world's cameras with the rig's nodes on wall time, a camera driver on its
    own clock) leave every camera pose unknown: no hottest point, no N_p window.
    """
    name = 'time base'
    if joints is None or not joints.stamps:
        return Finding(name, WARN, 'no joint_states heard: image stamps not compared',
                       'start dobot_driver and servo_driver')
    newest_joint = max(joints.stamps)
    offsets = {kind: max(stream.stamps) - newest_joint
               for kind, stream in sorted(images.items()) if stream is not None and stream.stamps}
    if not offsets:
        return Finding(name, WARN, 'no camera image heard: stamps not compared',
                       'see the camera rates')
    text = ', '.join(f'{kind} {offset:+.2f} s' for kind, offset in offsets.items())
    far = {kind: offset for kind, offset in offsets.items() if abs(offset) > tolerance}
    if far:
        return Finding(name, FAIL, f'images stamped on another clock than joint_states ({text}'
                       '): no image can be matched to an arm pose',
                       'run every node on one clock: with the simulated world, use_sim_time '
                       'true for all (helio sim does; helio rig --set NODE.use_sim_time=true); '
                       'on a real rig, camera drivers stamping with the system clock')
    return Finding(name, OK, f'newest images against the newest joint_states: {text}')


def check_calibrations(facts, expected=EXPECTED_CALIBRATIONS):
    """
    Return the findings of the calibration directory: each expected one present and usable.

    A calibration made for another rig description is refused by the nodes (FAIL: it
    measured another rig); a missing one is a WARN with how to make it.
    """
    findings = []
    by_name = {entry['name']: entry for entry in facts.entries}
    where = f'{facts.directory} ({facts.source})'
    for name in expected:
        entry = by_name.get(name)
        check = f'calibration {name}'
        if entry is None:
            findings.append(Finding(check, WARN, f'none in {where}', CALIBRATION_FIXES[name]))
        elif not entry['usable']:
            findings.append(Finding(check, FAIL, entry['reason'],
                                    CALIBRATION_FIXES[name] + f'; move {name} away first'))
        else:
            findings.append(Finding(check, OK, f'saved {entry.get("saved_at", "?")} by '
                                    f'{entry.get("made_by", "?")} for this rig '
                                    f'({facts.description}) in {where}'))
    for entry in facts.entries:
        if entry['name'] not in expected and not entry['usable']:
            findings.append(Finding(f'calibration {entry["name"]}', FAIL, entry['reason'],
                                    'calibrate again for this rig, or move the file away'))
    return findings


def check_emergency_stop(engaged):
    """Return the finding of the emergency stop (engaged: every goal is refused)."""
    name = 'emergency stop'
    if engaged is None:
        return Finding(name, WARN, 'its state was not heard (servo_driver not running?)',
                       'start servo_driver: it owns the emergency stop')
    if engaged:
        return Finding(name, FAIL, 'ENGAGED: every goal is refused',
                       'make the rig safe, then: helio reset')
    return Finding(name, OK, 'released')


# ---------------------------------------------------------------------------- the checklist
def run_checks(facts, settings=None):
    """Return every Finding of `facts`, in checklist order."""
    settings = settings or Settings()
    findings = []
    for device in ('dobot', 'servo'):
        status = facts.devices.get(device)
        findings.append(check_device(device, status, facts.namespace))
        findings.append(check_alarms(device, status))
    findings.append(check_homing(facts.devices.get('dobot'), facts.home_on_connect))
    findings.append(check_emergency_stop(facts.emergency_stop))
    for kind in ('rgb', 'thermal'):
        findings.append(check_camera_rate(kind, facts.images.get(kind),
                                          settings.expected_rate(kind),
                                          settings.rate_tolerance, facts.window))
        findings.append(check_camera_info(kind, facts.camera_infos.get(kind, []),
                                          facts.window))
    findings.append(check_thermal_range(facts.thermal, settings, facts.window))
    findings.append(check_marker(facts.spots, facts.window))
    findings.append(check_site(facts.site_files, facts.sample_site))
    longitude = None
    for path in facts.site_files.values():
        try:
            longitude = site_coordinates(path)[1]
            break
        except (OSError, ValueError, KeyError):
            continue
    if facts.clock is not None:
        findings.extend(check_clock(facts.clock, longitude, settings))
    findings.append(check_time_base(facts.images, facts.joint_states, settings.stamp_tolerance))
    if facts.calibration is not None:
        findings.extend(check_calibrations(facts.calibration))
    return findings


def passed(findings):
    """Return whether nothing failed."""
    return all(finding.level != FAIL for finding in findings)


def checklist_text(findings, facts=None):
    """Return the checklist as a person reads it, with a summary line."""
    lines = [finding.line() for finding in findings]
    counts = {level: sum(1 for f in findings if f.level == level) for level in LEVELS}
    where = ''
    if facts is not None:
        where = (f' (ROS_DOMAIN_ID {facts.domain or "0 (unset)"}, namespace '
                 f'{facts.namespace or "/"}, {facts.window:g} s after {facts.discovery:.1f} s '
                 'of discovery)')
    lines.append(f'helio doctor{where}: {counts[OK]} OK, {counts[WARN]} WARN, '
                 f'{counts[FAIL]} FAIL')
    return '\n'.join(lines)


def findings_json(findings):
    """Return the findings as plain data (``--json``)."""
    return {'passed': passed(findings), 'findings': [asdict(f) for f in findings]}


def _topic(namespace, name):
    return '/' + '/'.join(part for part in (namespace.strip('/'), name) if part)
