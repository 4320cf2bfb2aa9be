"""The simulated session behind the page: one :class:`~lapwrench.sim.loop.ClosedLoop` (world, simulated
sensors, controller, safety supervisor, through the one control loop), stepped one 1 ms tick at a time.

Threads: the runner (:mod:`lapwrench.ui.runner`) calls :meth:`Session.step`; the page's callbacks
only write the inputs (:attr:`Session.hand`, :attr:`Session.instruments`) or queue a request (a
parameter change, a reset, a resume) that the next tick carries out, all under :attr:`Session.lock`.
What the page draws comes from a :class:`Snapshot` taken every few ticks and from the
:class:`~lapwrench.ui.history.History`.

After every tick, each callable in :attr:`Session.on_tick` runs in the sim thread with the session
and the tick's result (``None`` while the supervisor holds the arm): the seam for a telemetry
publisher (and the laparoscope view's frame copy). Keep it short: it runs inside the real-time loop.

A hold (a supervisor alarm) keeps the world running with the arm held; :meth:`Session.resume`
restarts the control loop at the measured pose, the RCM point kept where the shaft meets it.
A parameter change (:meth:`Session.request_config`) builds a new controller at once. Once the arm is
nearly at rest (:data:`AT_REST_SPEED`) the supervisor stops it fully (its jerk-limited stop, a few
cycles), and the loop restarts with the new controller and a supervisor with the new thresholds that
resumes from the reference the robot holds (:meth:`SafetySupervisor.continue_from`), so the command
stream does not jump; while held, the change waits for the resume.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from lapwrench.config import Config
from lapwrench.controller import Controller, TickResult
from lapwrench.safety.supervisor import SafetySupervisor, SupervisorConfig
from lapwrench.sim.loop import ClosedLoop, SafetyStopError
from lapwrench.sim.scripts import TISSUE_DEPTH, park_instrument
from lapwrench.sim.surgeon import HousingDisturbance
from lapwrench.sim.world import CONTROL_DT
from lapwrench.ui.history import History, mode_index
from lapwrench.ui.inputs import HandInput, HandWrenchCache, UiInputError, checked_choice, checked_number
from lapwrench.ui.playback import PLAYABLE, ScriptPlayer, make_script
from lapwrench.ui.snapshot import Snapshot, take_snapshot

DETECTORS = ("projected", "shipped")
"""Instrument detectors offered on the page: projected simulator geometry (cheap) or the shipped YOLO."""
SAMPLE_EVERY = 20  # ticks between plotted samples (50 Hz)
SNAPSHOT_EVERY = 10  # ticks between snapshots for the page (100 Hz; the page draws at its own rate)
AT_REST_SPEED = 0.02  # rad/s: every joint slower than this counts as at rest for a parameter change
INSTRUMENT_REACH = 0.08  # m, how far from the tissue point below the incision an instrument tip may go
SHIFT = (0.0, 0.01)  # m, the Fig. 5 housing shift
KEPT_RECORDS = 10_000  # the closed loop's per-tick lists are trimmed to this many


def build_loop(cfg: Config, seed: int, detector: str) -> ClosedLoop:
    """A closed loop with ``detector`` (one of :data:`DETECTORS`). With ``projected`` the loop keeps the
    camera's clock and draws nothing (the page's view renders on its own thread, :mod:`lapwrench.ui.view`;
    live telemetry draws the few frames it sends); the shipped YOLO model detects on rendered frames."""
    checked_choice(detector, "detector", DETECTORS)
    closed = ClosedLoop(cfg, seed=seed, detector=detector)
    for i in range(closed.world.n_instruments):
        park_instrument(closed.world, i)
    return closed


def rcm_on_axis(closed: ClosedLoop) -> np.ndarray | None:
    """The controller's RCM point moved onto the shaft axis (None before the first start)."""
    p_E, d = closed.world.shaft_axis()
    rcm = closed.controller.rcm
    return None if rcm is None else p_E + float((rcm.p_R - p_E) @ d) * d


def restart_loop(closed: ClosedLoop, p_R: np.ndarray | None) -> None:
    """Restart the control loop at the measured pose: the controller reset at rest with RCM point
    ``p_R`` (see :func:`rcm_on_axis`), supervision restarted, and the session time kept equal to the
    simulated time. The F/T keeps its tare from the loop's first start (at ``closed.q0``), so the grip's
    weight is still taken off relative to there."""
    closed.loop.start(p_R, tare_q=closed.q0)
    closed.loop.t0 = 0.0  # session time = simulated time, as the sources and the detector count it


@dataclass
class InstrumentTarget:
    """Where the page wants an instrument: shown at (x, y) m from the tissue point below the incision,
    or withdrawn into its port."""

    visible: bool = False
    x: float = 0.0
    y: float = 0.0


@dataclass
class _Requests:
    config: tuple[Config, Controller] | None = None
    resume: bool = False
    disturbance: bool | None = None
    script: str | None = None  # a scenario to play (:data:`~lapwrench.ui.playback.PLAYABLE`)
    stop_script: bool = False
    instruments_dirty: bool = True
    errors: list[str] = field(default_factory=list)


class Session:
    """The simulated session (module docstring)."""

    def __init__(self, cfg: Config, seed: int = 0, detector: str = "projected",
                 history: History | None = None) -> None:
        self.seed = int(seed)
        self.detector = checked_choice(detector, "detector", DETECTORS)
        self.closed = build_loop(cfg, self.seed, self.detector)
        self.lock = threading.RLock()
        self.hand = HandInput()
        self.instruments = [InstrumentTarget() for _ in range(self.closed.world.n_instruments)]
        self.history = history or History()
        self.on_tick: list[Callable[[Session, TickResult | None], None]] = []
        # Called in the sim thread right after a snapshot that is the first to show a changed hand (the page
        # draws it at once instead of at its next period: a push shows without waiting for the page).
        self.on_hand_snapshot: list[Callable[[], None]] = []
        self.held: str | None = None
        self.alarms: list[str] = []
        self.max_rcm_error = 0.0  # m, physical, since the last reset_stats()
        self.snapshot: Snapshot | None = None
        self.ticks, self._req = 0, _Requests()
        self._disturbance: HousingDisturbance | None = None
        self._script: ScriptPlayer | None = None
        self._last: TickResult | None = None
        self._hand = HandWrenchCache()  # the page's hand as last set on the world
        self._hand_changed = False  # since the last snapshot
        self._changing = False  # a parameter change is stopping the arm to rest (:meth:`_apply_requests`)

    # -- what the page asks -------------------------------------------------------------------
    @property
    def cfg(self) -> Config:
        return self.closed.cfg

    @property
    def time(self) -> float:
        return self.closed.t

    @property
    def config_pending(self) -> bool:
        """A parameter change waits for the arm to come (nearly) to rest, stops it there and restarts the loop
        with the new parameters from the held reference (or waits for a resume)."""
        return self._req.config is not None

    def set_instrument(self, index: object, visible: object, x: object, y: object) -> None:
        """Show instrument ``index`` at (x, y) m from the tissue point, or withdraw it."""
        n = len(self.instruments)
        i = int(checked_number(index, "instrument", 0, n - 1))
        r = INSTRUMENT_REACH
        target = InstrumentTarget(bool(visible), checked_number(x, "instrument x (m)", -r, r),
                                  checked_number(y, "instrument y (m)", -r, r))
        with self.lock:
            self.instruments[i] = target
            self._req.instruments_dirty = True

    def set_disturbance(self, on: bool) -> None:
        """Shift the incision housing by :data:`SHIFT` (Fig. 5) from the next tick, or release it."""
        with self.lock:
            self._req.disturbance = bool(on)

    def play(self, name: object) -> None:
        """Play scenario ``name`` (:data:`~lapwrench.ui.playback.PLAYABLE`; UiInputError if unknown) from
        the next tick, in place of one playing; the page's hand still pushes (:mod:`lapwrench.ui.playback`)."""
        key = checked_choice(name, "scenario", tuple(PLAYABLE))
        with self.lock:
            self._req.script, self._req.stop_script = key, False

    def stop_script(self) -> None:
        """Stop the scenario playing (its hand lets go, the page's instruments come back)."""
        with self.lock:
            self._req.script, self._req.stop_script = None, True

    def resume(self) -> None:
        """Leave a hold at the next tick (no-op when not held)."""
        with self.lock:
            self._req.resume = True

    def request_config(self, cfg: Config) -> None:
        """Use ``cfg`` from the next tick at which the arm is at rest. The controller is built here, in
        the caller's thread (it may take a moment); UiInputError if it cannot be built."""
        try:
            controller = Controller(cfg, self.closed.model)
        except Exception as exc:  # a configuration the controller refuses: shown on the page
            raise UiInputError(f"parameters: {exc}") from exc
        with self.lock:
            self._req.config = (cfg, controller)

    def reset(self, cfg: Config | None = None, detector: str | None = None) -> None:
        """A fresh world and controller (the same configuration unless given; parameters accepted but not
        yet applied are applied by it); the inputs are kept. Built in the caller's thread, swapped in
        under the lock."""
        det = self.detector if detector is None else checked_choice(detector, "detector", DETECTORS)
        pending = self._req.config  # accepted parameters not yet applied: the fresh world starts with them
        closed = build_loop(cfg or (self.cfg if pending is None else pending[0]), self.seed, det)
        with self.lock:
            old, self.closed, self.detector = self.closed, closed, det
            self.held, self.alarms, self._last, self.snapshot = None, [], None, None
            self._changing = False
            self._disturbance = self._script = None
            later = self._req.config if self._req.config is not pending else None  # asked during the build
            self._req, self.max_rcm_error = _Requests(config=later), 0.0
            self.history.clear()
        old.world.close()

    def reset_stats(self) -> None:
        with self.lock:
            self.max_rcm_error = 0.0

    def pending_errors(self) -> list[str]:
        """Errors raised while applying the page's requests in the sim thread (drained)."""
        with self.lock:
            out, self._req.errors = self._req.errors, []
            return out

    # -- the tick -----------------------------------------------------------------------------
    def step(self) -> TickResult | None:
        """One 1 ms tick: requests, hand, instruments, the closed loop (or a held cycle), records."""
        with self.lock:
            self._apply_requests()
            grip = self._apply_hand()
            res = self._cycle(grip)
            self._after(res)
            return res

    def _cycle(self, grip: float) -> TickResult | None:
        c = self.closed
        if self._changing:
            self._change_cycle()
            return None
        if self.held is not None:
            self._held_cycle()
            return None
        dist = self._disturbance
        before = None if dist is None else (lambda t: dist.apply(c.world, c.t))
        try:
            res = c.step(grip, before_physics=before)
        except SafetyStopError as exc:
            self.held = str(exc.reason)
            self.alarms.append(f"t = {exc.time:.3f} s: {exc.reason}")
            return None
        self._last = res
        return res

    def _held_cycle(self) -> None:
        """One cycle of the supervisor's stop or hold, no controller; the world (hand, housing) goes on."""
        c = self.closed
        c.loop.hold_cycle()
        if self._disturbance is not None:
            self._disturbance.apply(c.world, c.t)
        c.t += CONTROL_DT

    def _change_cycle(self) -> None:
        """One cycle of the stop before a parameter change (the supervisor's jerk-limited stop, no
        controller); at rest the loop restarts with the new parameters. An alarm during the stop holds the
        arm as any alarm does; the change then waits for the resume."""
        self._held_cycle()
        c = self.closed
        sup = c.supervisor
        if sup.alarm:
            self._changing = False
            self.held = str(sup.alarm_reason)
            self.alarms.append(f"t = {c.t:.3f} s: {sup.alarm_reason}")
        elif sup.at_rest:
            self._changing = False
            self._restart()

    def _apply_hand(self) -> float:
        """The page's hand on the world, plus a playing scenario's (:mod:`lapwrench.ui.playback`). The
        hand stays on the world until changed: set again only when it changed (:class:`HandWrenchCache`)."""
        w = self.closed.world
        force, torque, changed = self._hand.wrench(self.hand, w.shaft_axis()[1], w)
        self._hand_changed |= self._hand.hand_changed
        if self._script is None:
            if changed:
                w.set_hand_wrench(force=force, torque=torque)
            return self.hand.grip_force
        grip, finished = self._script.apply(w, self.closed.t, force, torque, self.hand.grip_force)
        if finished:
            self._end_script()
        return grip

    def _end_script(self) -> None:
        """The scenario is over: only the page's hand from the next tick, and the page's instruments."""
        self._script = None
        self._req.instruments_dirty = True
        self._hand = HandWrenchCache()  # the script's hand is on the world: set the page's again

    def _apply_requests(self) -> None:
        r, c = self._req, self.closed
        if r.resume and self.held is not None and c.supervisor.at_rest:
            self._restart()
        r.resume = False
        if r.config is not None and self.held is None and not self._changing and self._at_rest():
            c.supervisor.stop(c.loop.session_time(), "parameter change")  # restarted at rest (_change_cycle)
            self._changing = True
        if r.disturbance is not None:
            self._disturbance = HousingDisturbance(start=c.t, shift=SHIFT) if r.disturbance else None
            if not r.disturbance:
                c.world.set_housing_load(np.zeros(3))
            r.disturbance = None
        if (r.stop_script or r.script is not None) and self._script is not None:
            self._end_script()
        if r.script is not None:
            self._script = ScriptPlayer(make_script(r.script, self.hand.grip_force), c.t)
        r.script, r.stop_script = None, False
        scripted = self._script is not None and self._script.script.moves_instruments  # it places them
        if (r.instruments_dirty or self.ticks % 100 == 0) and not scripted:  # the ports move with the housing
            self._place_instruments()
            r.instruments_dirty = False

    def _restart(self) -> None:
        """Restart the loop at the measured pose, with the pending configuration if there is one."""
        c, r = self.closed, self._req
        p_R = rcm_on_axis(c)
        if r.config is not None:
            cfg, controller = r.config
            r.config = None
            sup = SafetySupervisor(controller.model.limits, CONTROL_DT,
                                   SupervisorConfig.from_config(cfg, max_consecutive_misses=0))
            sup.continue_from(c.supervisor)  # at rest: the restart resumes from the reference it holds
            c.cfg, c.controller, c.loop.controller = cfg, controller, controller
            c.supervisor, c.loop.supervisor = sup, sup
        try:
            restart_loop(c, p_R)
        except Exception as exc:  # shown on the page; the arm stays held
            r.errors.append(f"restart failed: {exc}")
            return
        self.held = None

    def _at_rest(self) -> bool:
        return float(np.max(np.abs(self.closed.world.dq))) < AT_REST_SPEED

    def _place_instruments(self) -> None:
        c = self.closed
        base = c.world.incision_rest_position() + np.array([0.0, 0.0, -TISSUE_DEPTH])
        for i, target in enumerate(self.instruments):
            if target.visible:
                c.world.set_instrument_tip(i, base + np.array([target.x, target.y, 0.0]))
            else:
                park_instrument(c.world, i)

    def _after(self, res: TickResult | None) -> None:
        c = self.closed
        self.ticks += 1
        e = c.physical_rcm_error()
        self.max_rcm_error = max(self.max_rcm_error, e)
        if self.ticks % SAMPLE_EVERY == 0:
            self.history.append(c.t, self._sample(res, e))
        if self.ticks % SNAPSHOT_EVERY == 0 or self._hand_changed:
            self.snapshot = self._snapshot(e)
            if self._hand_changed:
                self._hand_changed = False
                for notify in self.on_hand_snapshot:
                    notify()
        if self.ticks % 1000 == 0:
            for records in (c.compute_us, c.events):
                del records[:-KEPT_RECORDS]
        for callback in self.on_tick:
            callback(self, res)

    def _sample(self, res: TickResult | None, rcm_error: float) -> dict[str, float]:
        c = self.closed
        out = {
            "RCM error (mm)": rcm_error * 1e3,
            "trocar force (N)": float(np.linalg.norm(c.world.contact_force())),
            "δ": 0.0 if res is None else res.delta,
            "mode": mode_index("held" if res is None else res.mode),
        }
        if res is not None:
            for name, w in res.wrenches.items():
                out[f"|F| {name}"] = float(np.linalg.norm(w[3:]))
        return out

    def _snapshot(self, rcm_error: float) -> Snapshot:
        return take_snapshot(
            self.closed, self._last, held=self.held, alarms=self.alarms, rcm_error=rcm_error,
            disturbance=self._disturbance is not None, script=self._script, pending_config=self._req.config is not None,
        )
