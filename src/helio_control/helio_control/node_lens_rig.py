"""
The lens planner node's side of the procedures' port (``LensRigPort``), one per goal.

``NodeLensRig`` answers a procedure's requests with the node's interfaces: moves are goals
of the drivers' ``move_arm`` and ``move_wrist`` (sent together, canceled with the goal),
observations come from the ``spot`` stream (``SpotWaiter``), the sun from ``sun/estimate``
and the ``estimate_sun`` service, the joints from ``joint_states``; what a calibration
measured is used, published and saved by the node. Nothing blocks: every wait is awaited in
the node's one-thread ``rclpy.spin``.
"""

import time
import traceback

from action_msgs.msg import GoalStatus
from helio_control.goal_sending import accepted, GoalNotRun, result_unless
from helio_control.procedures.lens_rig_port import GoalCanceled, GoalFailed, LensRigPort
from helio_msgs.action import FocusLens, MoveArm, MoveWrist
from helio_msgs.srv import EstimateSun
from helio_optics.node_kit import emergency_stop
from helio_optics.node_kit.awaitables import discovered, FirstOf, in_thread, sleep, within
from helio_optics.node_kit.conversions import stamp_from_seconds, stamp_to_seconds
import numpy as np


class _Unattended:
    """The goal handle of a move no client asked for (the lease's retreat): never canceled."""

    is_cancel_requested = False


UNATTENDED = _Unattended()


class SpotWaiter:
    """Collects the spot observations stamped after `after` until `count` arrived."""

    def __init__(self, after, count, accept):
        self.after, self.count, self.accept = after, count, accept
        self.messages = []
        self.refused = {}              # reason -> count, for the log
        self.future = FirstOf()

    def offer(self, message):
        """Take a spot observation; complete the future when enough were taken."""
        if self.future.done() or stamp_to_seconds(message.header.stamp) <= self.after:
            return
        if self.accept(message):
            self.messages.append(message)
        else:
            reason = message.reason or 'not accepted'
            self.refused[reason] = self.refused.get(reason, 0) + 1
        if len(self.messages) >= self.count:
            self.future.offer(self.messages)


def goal_runner(node, action_type, execute):
    """
    Return the execute callback of `node`'s action server running the procedure `execute`.

    One goal at a time on the node (``node.busy``; none while the emergency stop is
    engaged); the procedure gets a ``NodeLensRig`` of the goal; a ``GoalFailed`` or
    ``GoalCanceled`` ends the goal with its message, another exception as an internal error.
    A procedure other than a focus first disarms the focus lease (no client's lens to guard).
    """
    async def run(goal_handle):
        result = action_type.Result()
        if node.busy or node.emergency.engaged:
            result.success = False
            result.message = (emergency_stop.refusal(f'{action_type.__name__} goal')
                              if node.emergency.engaged
                              else 'busy: another lens_planner goal runs')
            goal_handle.abort()
            return result
        node.busy = True
        if action_type is not FocusLens:
            node.lease.disarm()       # its own procedure: no client's focus to guard
            node.at_heating = False
        try:
            await execute(NodeLensRig(node, goal_handle), goal_handle.request, result)
            result.success = True
            goal_handle.succeed()
        except GoalCanceled:
            result.success, result.message = False, 'canceled; the devices were stopped'
            goal_handle.canceled()
        except GoalFailed as failure:
            result.success, result.message = False, str(failure)
            goal_handle.abort()
        except Exception as error:      # a bug: end the goal with what happened
            result.success = False
            result.message = f'internal error: {type(error).__name__}: {error}'
            node.get_logger().error(traceback.format_exc())
            goal_handle.abort()
        finally:
            node.busy = False
        if result.success:
            node.get_logger().info(f'{action_type.__name__}: {result.message}')
        else:
            node.get_logger().warning(f'{action_type.__name__}: {result.message}')
        return result
    return run


class NodeLensRig(LensRigPort):
    """The procedures' port on the lens planner node (``node``) for one goal's handle."""

    def __init__(self, node, goal_handle):
        """Serve the procedures of the goal `goal_handle` (its cancel, its feedback)."""
        self.node, self.goal_handle = node, goal_handle

    settings = property(lambda self: self.node.settings)
    rig = property(lambda self: self.node.rig)
    nominal_rig = property(lambda self: self.node.nominal_rig)
    lens = property(lambda self: self.node.lens)
    spot_model = property(lambda self: self.node.spot_model)
    targeting = property(lambda self: self.node.targeting)
    site = property(lambda self: self.node.site)
    heating_distance = property(lambda self: self.node.heating_distance)
    world_calibrated = property(lambda self: self.node.world_calibrated)

    def _check_cancel(self):
        if self.goal_handle.is_cancel_requested:
            raise GoalCanceled()

    def joints_at(self, seconds):
        """Return the reported joints at image time `seconds` (joint_state_tolerance)."""
        return self.node.joints.at(seconds, self.node.joint_state_tolerance)

    def present_joints(self):
        """Return the present joints; GoalFailed when none are fresh."""
        return self.node.present_joints()

    async def camera(self):
        """Return the RGB camera; wait for rgb/camera_info at most observe_timeout."""
        node = self.node
        if node.camera is None and not await within(node, node.camera_seen,
                                                    node.observe_timeout):
            raise GoalFailed(f'no rgb/camera_info within {node.observe_timeout:g} s: is the '
                             'RGB camera running?')
        return node.camera

    def now(self):
        """Return the node clock [s]."""
        return self.node.now()

    def sun_ray(self):
        """Return the sun estimate's ray; GoalFailed when there is none."""
        return self.node.sun_ray()

    def has_sun(self):
        """Return whether a trustworthy sun estimate came."""
        return self.node.sun is not None

    async def estimate_sun(self, method, since, rig_calibration=None):
        """Return estimate_sun's answer; with `rig_calibration`, once it names that one."""
        deadline = time.monotonic() + self.node.server_timeout
        response = await self._estimate(method, since)
        if rig_calibration is None:
            return response
        while response.rig_calibration != rig_calibration and time.monotonic() < deadline:
            await sleep(self.node, 0.1, wall=True)
            response = await self._estimate(method, since)
        if response.rig_calibration != rig_calibration:
            raise GoalFailed('rig calibration applied, but the sun estimator did not take '
                             f'it within {self.node.server_timeout:g} s: its estimate used the '
                             f'rig calibration {response.rig_calibration!r}')
        return response

    async def _estimate(self, method, since):
        """
        Call estimate_sun on the spots imaged since `since` [s, node clock].

        The estimator keeps only the spots imaged with the lens still (its ``still_only``):
        those of the holds since then, not those of the moves between them, nor an earlier
        sweep's.
        """
        await self.discovered(self.node.estimator.service_is_ready,
                              'estimate_sun (is sun_estimator running?)')
        return await self.node.estimator.call_async(EstimateSun.Request(
            method=method, since=stamp_from_seconds(since)))

    def use_sun(self, estimate):
        """Use the sun estimate from now on."""
        self.node.sun = estimate

    def use_world(self, world_in_robot, world_yaw):
        """Use and publish T_robot_world."""
        self.node.publish_world(world_in_robot, world_yaw)

    def use_rig(self, flat, identity):
        """Use and publish the rig calibration."""
        self.node.publish_rig(flat, identity)

    def use_rig_parameters(self, parameters):
        """Plan with these rig parameters."""
        self.node.rig.set_parameters(parameters)

    def use_focus(self, heating_distance, min_area, fit_rms_relative, samples):
        """Use and publish the heating distance."""
        self.node.publish_focus(heating_distance, min_area, fit_rms_relative, samples)

    def save(self, name, tree, notes=None):
        """Save the calibration in calibration_dir."""
        return self.node.save(name, tree, notes)

    def feedback(self, message):
        """Publish the goal's feedback."""
        self.goal_handle.publish_feedback(message)

    def log(self, text, warning=False):
        """Log on the node's logger."""
        # one call site per severity: rclpy's logger refuses a second severity from a line
        if warning:
            self.node.get_logger().warning(text)
        else:
            self.node.get_logger().info(text)

    async def in_background(self, function):
        """Compute function() on a thread (the node spins on)."""
        return await in_thread(self.node, function)

    async def wait_for_inputs(self):
        """For startup_wait after the start, wait for the sun estimate and the joints."""
        node = self.node
        waited = time.monotonic() - node.started
        if waited < node.startup_wait and not node.inputs_heard():
            try:            # just started: the sun estimate and joints may be on their way
                await discovered(node, node.inputs_heard, node.startup_wait - waited,
                                 'the sun estimate and the joint states')
            except TimeoutError:
                pass        # sun_ray and present_joints say why

    def client_alive(self):
        """Return whether the lease's client (the painter) is heard."""
        return self.node.lease.alive(self.node.now(), time.monotonic())

    def placed(self, at_heating, alive):
        """Keep whether the lens is at the heating distance; tell the lease."""
        self.node.at_heating = at_heating
        self.node.lease.placed(at_heating, alive)

    async def discovered(self, ready, what):
        """Wait until `ready()` (a server discovered), at most server_timeout of wall time."""
        try:
            await discovered(self.node, ready, self.node.server_timeout, what)
        except TimeoutError as error:
            raise GoalFailed(str(error)) from None

    async def move(self, x):
        """Move arm and wrist to joints x together; return the joints the drivers reached."""
        self._check_cancel()
        node = self.node
        await self.discovered(lambda: node.arm.server_is_ready()
                              and node.wrist.server_is_ready(),
                              'move_arm or move_wrist (are dobot_driver and servo_driver '
                              'running and connected?)')
        arm_goal = MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE,
                                target=[float(v) for v in x[:3]] + [0.0])
        wrist_goal = MoveWrist.Goal(yaw=float(x[3]), pitch=float(x[4]))
        handles = []
        try:
            for client, goal, name in ((node.arm, arm_goal, 'move_arm'),
                                       (node.wrist, wrist_goal, 'move_wrist')):
                try:
                    handles.append(await accepted(
                        node, client, goal, name, node.goal_accept_timeout,
                        hint='is its driver running?', refused='another move running?'))
                except GoalNotRun as failure:
                    for handle in handles:           # the other device must not move alone
                        handle.cancel_goal_async()
                    raise GoalFailed(str(failure)) from None
                node.driver_goals.append(handles[-1])
            # a driver killed mid-move never answers (its server stays discovered for
            # seconds): its silence ends the wait, and the goals are canceled
            arm_reply, wrist_reply = await result_unless(node, handles, self._silent_drivers,
                                                         'the move was')
        except GoalNotRun as failure:
            raise GoalFailed(str(failure)) from None
        finally:
            for handle in handles:
                node.driver_goals.remove(handle)
        self._check_cancel()
        for reply, name in ((arm_reply, 'move_arm'), (wrist_reply, 'move_wrist')):
            if reply.status == GoalStatus.STATUS_UNKNOWN:
                raise GoalFailed(f'{name} no longer knew the goal when its result was asked '
                                 'for (expired on the driver)')
            if not reply.result.success:
                raise GoalFailed(f'{name} failed: {reply.result.message}')
        arm_result, wrist_result = arm_reply.result, wrist_reply.result
        return np.array([*arm_result.achieved_joints[:3], wrist_result.achieved_yaw,
                         wrist_result.achieved_pitch])

    def _silent_drivers(self):
        """Say which drivers' joint states stopped (device_silence of wall time), or ''."""
        return '; '.join(why for _, why in self.node.drivers.faults(time.monotonic()))

    async def observe(self, count, accept):
        """Return `count` spot observations imaged after now (after the settle time)."""
        node = self.node
        await sleep(node, node.settle_time)
        waiter = SpotWaiter(node.now(), count, accept)
        node.spot_waiters.append(waiter)
        timer = node.create_timer(node.observe_timeout,
                                  lambda: waiter.future.offer(list(waiter.messages)))
        try:
            messages = await waiter.future
        finally:
            node.spot_waiters.remove(waiter)
            node.destroy_timer(timer)
        if len(messages) < count:
            node.get_logger().warning(
                f'{len(messages)} of {count} spot observations accepted in '
                f'{node.observe_timeout:g} s; refused: {waiter.refused or "none arrived"}')
        self._check_cancel()
        return messages
