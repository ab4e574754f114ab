"""The demo's start of the master's task when a parameter answer is lost (no ROS graph).

Loaded run 13/3 (docs/reliability.md, seventh round): the master took its trajectory
parameters and ran its 4 s task while the runner, its spin thread receiving messages
all along, never got the set's answer; the runner then read the master's exit as a
death. These tests drive :func:`set_parameters_confirmed` with a stand-in for the
master's parameter services that loses answers or requests on purpose: the task must be
started exactly once, whatever is lost.
"""
from __future__ import annotations

import pytest
from rcl_interfaces.msg import SetParametersResult
from rcl_interfaces.srv import GetParameters, SetParametersAtomically
from rclpy.parameter import Parameter
from rclpy.task import Future

from grip_force_ros.demo.run import HOLD_MASTER, ProcessError, set_parameters_confirmed

TASK = {'trajectory': 'needle_grasp', 'trajectory_file': '', 'time_scale': 1.0}
WAIT = 0.05          # s, answer wait of these tests (the product's: ANSWER_WAIT)


class LossyMaster:
    """The master's parameter services, with chosen losses.

    ``lose`` lists, in order, what happens to each set request: 'answer' (taken, the
    answer lost), 'request' (never arrives), 'ok' (taken and answered); after the list,
    'ok'. ``lose_reads`` reads lose their answer first.
    """

    def __init__(self, lose=(), lose_reads=0, refuse=None):
        self.held = dict(HOLD_MASTER)
        self.plan = list(lose)
        self.lose_reads = lose_reads
        self.refuse = refuse
        self.sets = 0
        self.reads = 0
        self.task_starts = 0          # every taken set restarts the master's task

    def set_parameters_atomically(self, parameters):
        self.sets += 1
        future = Future()
        fate = self.plan.pop(0) if self.plan else 'ok'
        if fate == 'request':
            return future
        if self.refuse:
            future.set_result(SetParametersAtomically.Response(
                result=SetParametersResult(successful=False, reason=self.refuse)))
            return future
        self.held.update({p.name: p.value for p in parameters})
        self.task_starts += 1
        if fate == 'ok':
            future.set_result(SetParametersAtomically.Response(
                result=SetParametersResult(successful=True)))
        return future

    def get_parameters(self, names):
        self.reads += 1
        future = Future()
        if self.lose_reads:
            self.lose_reads -= 1
            return future
        future.set_result(GetParameters.Response(
            values=[Parameter(n, value=self.held[n]).get_parameter_value() for n in names]))
        return future


def alive():
    """The master's process is alive (check_alive raises when it is not)."""


def test_an_answered_set_is_sent_once():
    master = LossyMaster()
    assert set_parameters_confirmed(master, TASK, alive, timeout=5.0, answer_wait=WAIT) == 'answered'
    assert (master.sets, master.reads, master.task_starts) == (1, 0, 1)
    assert master.held == TASK


def test_a_lost_answer_is_confirmed_by_a_read_and_the_task_not_restarted():
    # the failure of loaded run 13/3: taken, answer lost (the code before waited
    # for the answer alone, until the master had finished its task and exited)
    master = LossyMaster(lose=['answer'])
    assert set_parameters_confirmed(master, TASK, alive, timeout=5.0,
                                    answer_wait=WAIT) == 'confirmed by a read'
    assert (master.sets, master.task_starts) == (1, 1)
    assert master.reads == 1


def test_lost_reads_are_asked_again_before_anything_is_sent_again():
    master = LossyMaster(lose=['answer'], lose_reads=3)
    assert set_parameters_confirmed(master, TASK, alive, timeout=5.0,
                                    answer_wait=WAIT) == 'confirmed by a read'
    assert (master.sets, master.reads, master.task_starts) == (1, 4, 1)


def test_a_lost_request_is_sent_again_once_the_master_is_seen_without_it():
    master = LossyMaster(lose=['request'])
    assert set_parameters_confirmed(master, TASK, alive, timeout=5.0,
                                    answer_wait=WAIT) == 'sent again'
    assert (master.sets, master.reads, master.task_starts) == (2, 1, 1)
    assert master.held == TASK


def test_a_lost_request_then_a_lost_answer():
    master = LossyMaster(lose=['request', 'answer'])
    assert set_parameters_confirmed(master, TASK, alive, timeout=5.0,
                                    answer_wait=WAIT) == 'sent again'
    assert (master.sets, master.reads, master.task_starts) == (2, 2, 1)


def test_a_refusal_is_raised_with_its_reason():
    master = LossyMaster(refuse='time_scale out of range')
    with pytest.raises(ProcessError, match='time_scale out of range'):
        set_parameters_confirmed(master, TASK, alive, timeout=5.0, answer_wait=WAIT)
    assert master.task_starts == 0


def test_a_master_that_never_answers_times_out_saying_so():
    master = LossyMaster(lose=['request'] * 1000, lose_reads=1000)
    with pytest.raises(ProcessError, match='no answer to setting'):
        set_parameters_confirmed(master, TASK, alive, timeout=0.5, answer_wait=WAIT)
    assert master.task_starts == 0


def test_a_dead_master_is_reported_while_waiting():
    master = LossyMaster(lose=['answer'], lose_reads=1000)

    def dead():
        raise ProcessError('master exited with code 1')

    with pytest.raises(ProcessError, match='exited with code 1'):
        set_parameters_confirmed(master, TASK, dead, timeout=5.0, answer_wait=WAIT)


def test_a_master_that_finished_its_task_before_any_answer_came_took_the_set():
    # loaded run 17/3: the set's answer and the confirming read were both lost while the
    # master ran its 4 s task and exited with code 0 (the runner raised "master exited")
    master = LossyMaster(lose=['answer'], lose_reads=1000)
    exited = []

    def finished():
        # the master exits once its task has run (here: after two reads went unanswered)
        if master.reads >= 2:
            exited.append(True)
        return bool(exited)

    assert set_parameters_confirmed(master, TASK, alive, timeout=5.0, answer_wait=WAIT,
                                    finished=finished) == 'finished before its answer'
    assert (master.sets, master.task_starts) == (1, 1)


def test_an_answer_that_came_wins_over_a_finished_master():
    master = LossyMaster()
    assert set_parameters_confirmed(master, TASK, alive, timeout=5.0, answer_wait=WAIT,
                                    finished=lambda: True) == 'answered'
