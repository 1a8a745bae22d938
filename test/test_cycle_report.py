"""The demo report's acceleration axes show the signal, not a stall's spikes (issue 28, item 7)."""

from __future__ import annotations

import numpy as np

from excavator_kinematics.demo.cycle_report import spike_limit


def test_the_axis_follows_the_signal_whatever_share_of_spikes() -> None:
    """A +-20 deg/s^2 signal at 100 Hz for 41 s with 1.5 % of its samples replaced by +-240 spikes
    (the issue's fig. 11; a 99.5th percentile would follow the spikes): the axis shows the whole
    signal and stays near it."""
    t = np.arange(4100) * 0.01
    signal = 20.0 * np.sin(t)
    rng = np.random.default_rng(11)
    spiked = signal.copy()
    at = rng.choice(len(t), 60, replace=False)
    spiked[at] = rng.choice([-240.0, 240.0], len(at))
    limit = spike_limit(spiked)
    assert 20.0 <= limit <= 26.0
    assert np.percentile(np.abs(spiked), 99.5) > 200.0  # what the old bulk rule would have followed
    # Several columns (x, y, z): the largest signal sets the axis; NaN is ignored.
    columns = np.stack((spiked, 0.1 * signal, np.full_like(signal, np.nan)), axis=1)
    assert spike_limit(columns) == limit


def test_a_clean_signal_keeps_its_peaks() -> None:
    signal = 3.0 * np.sin(np.linspace(0.0, 20.0, 2000))
    assert 3.0 * 1.19 <= spike_limit(signal) <= 3.0 * 1.21
