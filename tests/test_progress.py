"""The time-left estimate of long loops (diegocal.progress), on a clock the test moves."""

from diegocal.progress import Eta, duration


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_time_left_is_the_mean_time_per_item_times_the_items_left():
    clock = Clock()
    eta = Eta(10, clock=clock)
    assert eta.left(0) is None and eta.text(0) == "0/10, 0 s so far"
    clock.now += 12.0  # 3 items in 12 s: 4 s each, 7 left
    assert eta.left(3) == 28.0
    assert eta.text(3) == "3/10, 12 s so far, about 28 s left"
    clock.now += 28.0
    assert eta.text(10) == "10/10, 40 s so far"


def test_reports_are_spaced_and_a_reported_loop_reports_its_end():
    clock = Clock()
    short = Eta(2, every=5.0, clock=clock)
    assert not short.due(1) and not short.due(2)  # a loop shorter than ``every`` says nothing
    eta = Eta(4, every=5.0, clock=clock)
    clock.now += 5.0
    assert eta.due(1)
    clock.now += 1.0
    assert not eta.due(2)
    clock.now += 5.0
    assert eta.due(3)
    assert eta.due(4)  # the last item, however soon


def test_durations_read_at_a_glance():
    assert [duration(s) for s in (7.6, 200, 3900)] == ["8 s", "3 min 20 s", "1 h 05 min"]
