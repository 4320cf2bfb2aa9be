"""lapwrench.hardware.rt.peers: the child notices a peer process that exited (pidfd) or stopped
beating (heartbeat age), and not one that is merely starting up."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Iterator

import numpy as np
import pytest

from lapwrench.hardware.rt.peers import PeerSpec, PeerWatch


@pytest.fixture
def sleeper() -> Iterator[subprocess.Popen[bytes]]:
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_a_beating_peer_is_fine_and_a_silent_one_is_hung() -> None:
    beats = np.zeros(8)
    watch = PeerWatch(beats, [PeerSpec("feeder", beat=0, timeout=0.05)])
    now = time.monotonic()
    watch.arm(now)
    beats[0] = now
    assert watch.check(now + 0.04) is None
    hit = watch.check(now + 0.2)
    assert hit is not None
    message, peer = hit
    assert peer.name == "feeder" and message == "no heartbeat from the feeder for 200 ms (> 50 ms): hung"
    watch.close()


def test_the_start_up_is_not_a_hang_until_the_watch_is_armed() -> None:
    beats = np.zeros(8)
    watch = PeerWatch(beats, [PeerSpec("detector", beat=2, timeout=0.1)])
    now = time.monotonic()
    watch.arm(now)  # never beat yet: the age counts from the arming
    assert watch.check(now + 0.05) is None
    message, _ = watch.check(now + 0.5) or ("", None)
    assert "no heartbeat from the detector for inf ms" in message
    watch.close()


def test_a_peer_that_exits_is_named_at_once(sleeper: subprocess.Popen[bytes]) -> None:
    beats = np.zeros(8)
    peer = PeerSpec("parent", beat=0, timeout=10.0, pid=sleeper.pid)
    watch = PeerWatch(beats, [peer])
    now = time.monotonic()
    beats[0] = now
    assert watch.check(now) is None
    sleeper.kill()
    sleeper.wait()
    hit = watch.check(time.monotonic())
    assert hit == (f"parent process (pid {sleeper.pid}) exited", peer)
    watch.close()
    watch.close()  # idempotent


def test_after_an_exited_peer_is_forgotten_the_others_are_watched_again(sleeper: subprocess.Popen[bytes]) -> None:
    """The child forgets a peer once it has reported it; the watch then goes on checking the rest (before,
    the exited peer's pidfd stayed in the poll and was reported every cycle, hiding the others' hangs)."""
    beats = np.zeros(8)
    gone = PeerSpec("detector", beat=2, timeout=10.0, pid=sleeper.pid)
    feeder = PeerSpec("feeder", beat=0, timeout=0.05)
    watch = PeerWatch(beats, [gone, feeder])
    now = time.monotonic()
    watch.arm(now)
    beats[0] = beats[2] = now
    sleeper.kill()
    sleeper.wait()
    hit = watch.check(now)
    assert hit is not None and hit[1] is gone
    watch.forget(gone)
    assert watch.check(now) is None  # the detector is not named again
    hit = watch.check(now + 0.2)  # the feeder stops beating: noticed
    assert hit is not None and hit[1] is feeder
    watch.close()


def test_a_peer_gone_before_the_watch_starts_is_named_at_the_first_check(sleeper: subprocess.Popen[bytes]) -> None:
    sleeper.kill()
    sleeper.wait()
    peer = PeerSpec("parent", beat=0, timeout=10.0, pid=sleeper.pid)
    watch = PeerWatch(np.zeros(8), [peer])
    assert watch.check(time.monotonic()) == (f"parent process (pid {sleeper.pid}) exited", peer)
    watch.close()


def test_a_heartbeat_stamp_that_is_not_a_number_counts_as_no_heartbeat() -> None:
    """A corrupt stamp (NaN) ages like a peer that never beat: hung after its timeout (before, the NaN made
    every age comparison false, and the peer was never found hung)."""
    beats = np.zeros(8)
    watch = PeerWatch(beats, [PeerSpec("feeder", beat=0, timeout=0.05)])
    now = time.monotonic()
    watch.arm(now)
    beats[0] = np.nan
    assert watch.check(now + 0.04) is None
    hit = watch.check(now + 0.2)
    assert hit is not None and hit[0] == "no heartbeat from the feeder for inf ms (> 50 ms): hung"
    watch.close()
