"""The demo's start of the master's task when a parameter answer is lost (no ROS graph).

The fault: the master takes its trajectory parameters and runs its 4 s task while the
runner, its spin thread receiving messages all along, never gets the set's answer; the
runner would then read the master's exit as a death. These tests drive
:func:`set_parameters_confirmed` with a stand-in for the master's parameter services that
loses answers or requests on purpose: the task must be started exactly once, whatever is
lost.
"""
from __future__ import annotations

import threading
import time

import pytest
from rcl_interfaces.msg import SetParametersResult
from rcl_interfaces.srv import GetParameters, SetParametersAtomically
from rclpy.parameter import Parameter
from rclpy.task import Future

from grip_force_ros.lab.demo.run import HOLD_MASTER, NoAnswer, ProcessError, set_parameters_confirmed

TASK = {'trajectory': 'needle_grasp', 'trajectory_file': '', 'time_scale': 1.0}
WAIT = 0.05          # s, answer wait of these tests (the product's: ANSWER_WAIT)


class LossyMaster:
    """The master's parameter services, with chosen losses.

    ``lose`` lists, in order, what happens to each set request: 'answer' (taken, the
    answer lost), 'request' (never arrives), 'late' (taken, answered after ``late`` s),
    'ok' (taken and answered); after the list, 'ok'. ``lose_reads`` reads lose their
    answer first.
    """

    def __init__(self, lose=(), lose_reads=0, refuse=None, late=0.0):
        self.late = late
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
        answer = SetParametersAtomically.Response(result=SetParametersResult(successful=True))
        if fate == 'ok':
            future.set_result(answer)
        elif fate == 'late':
            timer = threading.Timer(self.late, future.set_result, (answer,))
            timer.daemon = True
            timer.start()
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
    # taken, answer lost: waiting for the answer alone would last until the master had
    # finished its task and exited
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
    # the set's answer and the confirming read both lost while the master runs its 4 s
    # task and exits with code 0: not "master exited"
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


# ---------------------------------------------------------------- bounded retry
def test_a_late_answer_to_the_first_set_is_taken_after_reads_went_unanswered():
    # not "no answer to setting [...] within 15 s": an answer that comes after its request's
    # 2 s wait (behind the recorder's backlog) is still taken
    master = LossyMaster(lose=['late'], lose_reads=1000, late=6 * WAIT)
    assert set_parameters_confirmed(master, TASK, alive, timeout=5.0,
                                    answer_wait=WAIT) == 'answered'
    assert (master.sets, master.task_starts) == (1, 1) and master.reads >= 1


def test_a_master_that_ignores_its_first_requests_is_asked_again_until_it_answers():
    # the set and the first two reads go unanswered; the third read shows the set lost
    master = LossyMaster(lose=['request'], lose_reads=2)
    assert set_parameters_confirmed(master, TASK, alive, timeout=5.0,
                                    answer_wait=WAIT) == 'sent again'
    assert (master.sets, master.reads, master.task_starts) == (2, 3, 1)
    assert master.held == TASK


def test_the_retry_is_bounded_in_requests_and_says_what_it_waited_for():
    master = LossyMaster(lose=['request'] * 1000, lose_reads=1000)
    started = time.monotonic()
    with pytest.raises(NoAnswer) as caught:
        set_parameters_confirmed(master, TASK, alive, timeout=60.0, answer_wait=WAIT,
                                 attempts=4, whom="the master's parameter services")
    waited = time.monotonic() - started
    error = caught.value
    assert master.sets + master.reads == 4 and (error.sets, error.reads) == (1, 3)
    assert waited < 2.0 and error.waited == pytest.approx(waited, abs=0.1)
    text = str(error)
    assert text.startswith("no answer to setting ['trajectory', 'trajectory_file', 'time_scale'] "
                           "from the master's parameter services: 1 set request(s) and 3 "
                           'read(s) sent over '), text
    assert isinstance(error, ProcessError) and master.task_starts == 0


def test_the_retry_is_bounded_in_time():
    master = LossyMaster(lose=['request'] * 1000, lose_reads=1000)
    started = time.monotonic()
    with pytest.raises(NoAnswer, match='no answer to setting'):
        set_parameters_confirmed(master, TASK, alive, timeout=0.4, answer_wait=WAIT,
                                 attempts=1000)
    assert time.monotonic() - started < 0.4 + 0.2
    # each unanswered request doubled the next one's wait: a few requests, not one per WAIT
    assert master.sets + master.reads <= 5
