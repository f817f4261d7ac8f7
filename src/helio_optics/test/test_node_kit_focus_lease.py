"""The focus lease: when a lens left at the heating distance is taken away."""

from helio_optics.node_kit.focus_lease import FocusLease
import pytest


def test_a_lens_placed_for_a_live_client_is_taken_away_once_both_clocks_say_silent():
    lease = FocusLease(timeout=1.0, wall_timeout=0.5)
    lease.heard(10.0, 100.0)
    alive = lease.alive(10.2, 100.1)
    lease.placed(at_heating=True, alive_when_asked=alive)
    assert alive and lease.armed
    assert not lease.expired(10.9, 100.9)        # node clock within the lease
    # a world 10x faster than the client: 1.5 s simulated but 0.15 s wall is no silence
    assert not lease.expired(11.5, 100.15)
    # a paused world: 0 s simulated whatever the wall says is no silence either
    assert not lease.expired(10.0, 103.0)
    assert lease.expired(11.5, 100.6)            # both silent: take the lens away
    lease.heard(11.6, 100.7)                     # alive again: held again
    assert not lease.expired(11.7, 100.8)


def test_a_lens_off_the_heating_distance_or_placed_without_a_heartbeat_is_never_taken():
    lease = FocusLease()
    lease.placed(at_heating=True, alive_when_asked=lease.alive(5.0, 5.0))
    assert not lease.armed                       # an operator's goal: nobody to outlive
    assert not lease.expired(1e6, 1e6)
    lease.heard(5.0, 5.0)
    lease.placed(at_heating=False, alive_when_asked=True)
    assert not lease.expired(100.0, 100.0)       # retreated already
    lease.placed(at_heating=True, alive_when_asked=True)
    lease.disarm()
    assert not lease.expired(100.0, 100.0)
    with pytest.raises(ValueError):
        FocusLease(timeout=0.0)
