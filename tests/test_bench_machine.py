"""The machine facts ``rdm bench`` records: the hypervisor's steal share during a run."""

from __future__ import annotations

import os
import time

import pytest

from rdm.bench.machine import cpu_ticks, steal_share


def test_steal_share_is_steal_over_the_cpu_time_wanted():
    # user nice system idle iowait irq softirq steal
    start = [1000, 0, 200, 5000, 10, 0, 5, 100]
    end = [1600, 0, 260, 5900, 10, 0, 15, 230]
    # wanted: 600 user + 60 system + 10 softirq + 130 steal = 800; idle/iowait left out
    assert steal_share(start, end) == pytest.approx(130 / 800)


@pytest.mark.parametrize(
    ("start", "end"),
    [
        (None, [0] * 8),
        ([0] * 8, None),
        ([0] * 7, [0] * 7),  # not the 8 counters
        ([5, 0, 0, 0, 0, 0, 0, 0], [4, 0, 0, 0, 0, 0, 0, 0]),  # a counter went back
        ([0, 0, 0, 10, 3, 0, 0, 0], [0, 0, 0, 90, 4, 0, 0, 0]),  # only idle: nothing wanted
    ],
)
def test_steal_share_without_a_meaningful_interval_is_none(start, end):
    assert steal_share(start, end) is None


def test_cpu_ticks_count_up_on_this_linux():
    if not os.path.exists("/proc/stat"):
        pytest.skip("no /proc/stat: not a Linux kernel (the counters are Linux's)")
    before = cpu_ticks()
    assert before is not None  # present but unread would be a parsing defect
    deadline = time.monotonic() + 0.1
    while time.monotonic() < deadline:  # busy: user time passes
        pass
    after = cpu_ticks()
    assert after is not None and len(before) == len(after) == 8
    assert all(b >= a for a, b in zip(before, after, strict=True))
    share = steal_share(before, after)
    assert share is not None and 0.0 <= share <= 1.0
