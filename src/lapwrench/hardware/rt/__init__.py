"""The 1 kHz control loop in its own process, isolated from the GIL of everything else.

Process layout (``lapwrench run`` by default)::

    parent (CLI, UI)                          real-time child (spawned, never forked)
    ----------------                          ---------------------------------------
    tactile serial reader ─┐                  robot (pylibfranka / franky-sim / SimRobot)
    feeder thread ─────────┼─ tactile slot ─▶ controller, supervisor
      (+ parent heartbeat) ┘                  F/T UDP socket, drained non-blocking each cycle
    camera ─▶ frame slot ─▶ detector process ─ instruments slot ─▶ (read each cycle)
    log drain thread ◀──── log ring + event ring ◀── ControlLoop's logger (never blocks)
    RunLogger (MCAP writer)
    monitor: child exit code + heartbeat       heartbeat, peer watch (pidfd + heartbeats)

All of it lives in one shared-memory :class:`~lapwrench.hardware.shm.Bus` (:func:`bus_layout`):
control words (stop request, phase, cycle count), heartbeat stamps (``time.monotonic()``, one clock
for all processes), the tactile and instrument latest-value slots (seqlocks, ≤ 16 points), and two
bounded rings from the child: cycle records (fixed float64 rows, :class:`CycleCodec`) and events
(fixed byte rows). A full ring drops and counts; the child never waits on the parent. A pipe carries
the start-up handshake (ready / go / error) and, once, the final :class:`LoopStats`.

What happens on each fault
--------------------------
* **Feeder (parent) dies** (crash, SIGKILL): the child polls the parent's pidfd each cycle → alarm
  ``peer_died`` at the next cycle → the supervisor's jerk-limited stop to rest → the child ends.
* **Feeder hangs** (deadlock, SIGSTOP, starved): its heartbeat is older than ``feeder_timeout``
  (default 0.5 s) → alarm ``peer_hung`` → stop to rest. In both cases the inputs it fed read as
  stale from then on. Before that, the tactile sample's own max age (0.1 s) has already switched
  the handle wrench off, as for any silent sensor; the timeout only decides when a silent *process*
  stops the arm. It is not shorter because the parent is an ordinary (not real-time) process: on
  this shared 2-core machine under load its feeder thread was seen to go 157 ms without running.
* **Detector process dies or hangs**: the same with its pid and ``detector_timeout`` (1.0 s; the
  instruments' max age, 0.2 s, switches the tracking wrench off first).
* **Corrupt shared memory** (a non-finite value, a point count out of range, a stamp in the
  future): alarm ``ipc_corrupt`` naming the slot → stop to rest. A slot left mid-write reads as
  stale.
* **Child dies or hangs**: the parent sees its exit code or a heartbeat older than
  ``child_timeout`` (0.5 s), logs ``rt_process_died``/``rt_process_hung`` and raises
  :class:`RtProcessError` (a hung child is killed). Nothing is left to command the robot: on a real
  Franka, libfranka's controller stops the arm by itself when commands stop arriving
  (``communication_constraints_violation``), which is the stop of last resort; franky-sim and the
  simulated robot just stop stepping.
* **SIGINT (Ctrl-C), SIGTERM or SIGHUP in the parent** (:mod:`lapwrench.hardware.run_common`): the
  CLI sets the stop request in shared memory and logs ``stop_requested`` with the signal's name;
  the child's loop stops to rest through the supervisor, sends its statistics, and the parent
  finalizes the log and prints the summary (``stop_reason``). Further signals meanwhile are
  ignored with a "please wait" line. The stop stays bounded: the loop's own stop deadline
  (``RtSpec.stop_timeout``, robot time), the heartbeat watch, and ``RtProcess.stop_wait`` (30 s of
  wall time from the request to the end of the child's loop; then it is killed as hung).
  The child ignores SIGINT (the terminal sends it to the whole process group) and treats its own
  SIGTERM or SIGHUP (a closed terminal hangs up the whole group) as a stop request, reported as
  ``stop_signal``.

Real-time settings (:class:`RtOptions`): SCHED_FIFO and CPU affinity when permitted, one warning
when not (like panda-py), and the garbage collector frozen in the loop.
"""

from lapwrench.hardware.rt.bus import (
    BEAT_CHILD,
    BEAT_DETECTOR,
    BEAT_PARENT,
    CTL_CYCLES,
    CTL_DET_ERRORS,
    CTL_DET_FRAMES,
    CTL_DET_STOP,
    CTL_PHASE,
    CTL_STOP,
    EVENT_BYTES,
    MAX_POINTS,
    PHASE_DONE,
    PHASE_READY,
    PHASE_RUNNING,
    PHASE_STARTING,
    TACTILE_N,
    bus_layout,
)
from lapwrench.hardware.rt.codec import (
    INTERN,
    CycleCodec,
    ShmLogSink,
)
from lapwrench.hardware.rt.factories import (
    franka_factory,
    sim_factory,
)
from lapwrench.hardware.rt.inputs import (
    ShmInput,
)
from lapwrench.hardware.rt.options import (
    RtOptions,
    apply_realtime,
)
from lapwrench.hardware.rt.parent import (
    RtProcess,
)
from lapwrench.hardware.rt.peers import (
    PeerSpec,
    PeerWatch,
)
from lapwrench.hardware.rt.spec import (
    FtSpec,
    RtProcessError,
    RtResult,
    RtSpec,
)

__all__ = [
    "BEAT_CHILD",
    "BEAT_DETECTOR",
    "BEAT_PARENT",
    "CTL_CYCLES",
    "CTL_DET_ERRORS",
    "CTL_DET_FRAMES",
    "CTL_DET_STOP",
    "CTL_PHASE",
    "CTL_STOP",
    "EVENT_BYTES",
    "INTERN",
    "MAX_POINTS",
    "PHASE_DONE",
    "PHASE_READY",
    "PHASE_RUNNING",
    "PHASE_STARTING",
    "TACTILE_N",
    "CycleCodec",
    "FtSpec",
    "PeerSpec",
    "PeerWatch",
    "RtOptions",
    "RtProcess",
    "RtProcessError",
    "RtResult",
    "RtSpec",
    "ShmInput",
    "ShmLogSink",
    "apply_realtime",
    "bus_layout",
    "franka_factory",
    "sim_factory",
]
