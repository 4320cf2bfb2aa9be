"""One closed loop in the simulated world: sensors → controller → robot, at 1 kHz.

Everything the controller sees comes from a simulated sensor (F/T, tactile array, joint-torque
based external force, camera). Instrument image points come from a detector run on the rendered
25 fps frames, asynchronously with a modelled latency (the shipped YOLO model by default), or —
when asked for — from the projection of the simulator's known instrument geometry (reported as such);
the detectors are built in :mod:`lapwrench.sim.detectors`.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from lapwrench.config import Config
from lapwrench.controller import Controller, TickResult
from lapwrench.loop import ControlLoop
from lapwrench.loop_stats import Cycle
from lapwrench.perception.async_detect import SimulatedAsyncDetector
from lapwrench.robot.arms import arm_spec
from lapwrench.robot.model import RobotModel
from lapwrench.safety.supervisor import SafetySupervisor, SupervisorConfig
from lapwrench.sensors import InstrumentObservation
from lapwrench.sim.camera import NO_IMAGE, PendingFrame, SimCamera, frame_hold
from lapwrench.sim.detectors import make_detector
from lapwrench.sim.robot import ForceEstimateConfig, SimRobot
from lapwrench.sim.scene.build import Scene, build_scene
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.sensors import SimForceTorqueSensor, TactileGripModel
from lapwrench.sim.variation import CorruptedDetector, WorldVariation
from lapwrench.sim.world import CONTROL_DT, SimWorld
from lapwrench.sources import Observable, Source, simulated_input
from lapwrench.wrenches.registry import input_specs

# Franka-like joint torque sensing imperfections behind the external force estimate: white noise, and
# a constant bias per joint from the robot's spec (ClosedLoop uses its arm's; TORQUE_BIAS is the Panda's).
TORQUE_NOISE = 0.05  # N m, white
TORQUE_BIAS = arm_spec("panda").sim_torque_bias  # N m


class SafetyStopError(RuntimeError):
    """The safety supervisor stopped the robot; ``time`` (s) and ``reason`` say when and why."""

    def __init__(self, time: float, reason: object) -> None:
        self.time = time
        self.reason = reason
        super().__init__(f"safety supervisor stopped the robot at t = {time:.3f} s: {reason}")


@functools.lru_cache(maxsize=8)
def built_scene(config: SceneConfig) -> Scene:
    """:func:`~lapwrench.sim.scene.build.build_scene`, once per configuration in a process: every world
    copies the scene's model before it writes to it (:class:`SimWorld`), so the runs of one configuration
    share it (the demo's scenarios build some forty loops; a build costs a few hundred ms)."""
    return build_scene(config)


_ZERO_WRENCH = np.zeros(6)  # a paper cue the configuration switched off


def _as_column(values: list | np.ndarray) -> list | np.ndarray:
    """A trace column as one array (what :meth:`Trace.__getitem__` gives), or the list itself when its
    rows do not stack into one (ragged rows)."""
    try:
        return np.asarray(values)
    except ValueError:
        return values


@dataclass
class Trace:
    """Per-tick records of one run: a list per column while running; :meth:`__getitem__` gives a column
    as a fresh array. Pickled (a demo worker's results, a study's runs) as one array per column: a
    list of a run's tens of thousands of small per-tick objects takes seconds to pickle and unpickle,
    its array milliseconds (the unpickled trace reads the same; :meth:`add` goes on with a list)."""

    columns: dict[str, list | np.ndarray] = field(default_factory=dict)

    def add(self, **values: object) -> None:
        cols = self.columns
        for k, v in values.items():
            col = cols.get(k)
            if col is None:
                col = cols[k] = []
            elif type(col) is not list:  # an array column (an unpickled trace): rows are appended to a list
                col = cols[k] = list(col)
            col.append(v)

    def __getitem__(self, key: str) -> np.ndarray:
        col = self.columns[key]
        return col.copy() if isinstance(col, np.ndarray) else np.asarray(col)

    def __getstate__(self) -> dict[str, object]:
        return {"columns": {k: _as_column(v) for k, v in self.columns.items()}}

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)

    def __contains__(self, key: str) -> bool:
        return key in self.columns


CycleObserver = Callable[["ClosedLoop", Cycle], None]
FrameObserver = Callable[["ClosedLoop", np.ndarray, float], None]  # an observer's optional ``frame`` method
_OBSERVERS: list[CycleObserver] = []


@contextlib.contextmanager
def observe_cycles(observer: CycleObserver) -> Iterator[None]:
    """Every :class:`ClosedLoop` built while this is active calls ``observer(loop, cycle)`` after each
    of its cycles (the command sent), and ``observer.frame(loop, image, t)`` with each camera frame if
    the observer has that method (an empty image when the loop draws none, :class:`ClosedLoop`): how an
    application above the simulation (live telemetry) sees the runs of scenarios that build their own loops."""
    _OBSERVERS.append(observer)
    try:
        yield
    finally:
        _OBSERVERS.remove(observer)


class ClosedLoop:
    """The world, its sensors and the controller, stepped together through the one control loop
    (:class:`lapwrench.loop.ControlLoop`) on the simulated robot and simulated sources.

    ``world`` varies the simulated world (:class:`~lapwrench.sim.variation.WorldVariation`): the
    trocar's stiffness, the detector's latency (unless ``detection_latency`` is given), dropout and
    noise. The hands are the scenario's (they scale with :meth:`WorldVariation.hand`).

    The camera (:attr:`camera`) draws its frames only for an image detector or ``on_frame``. A run with the
    projected detector and no ``on_frame`` keeps its clock and draws nothing (the same detections at the
    same capture times); its frame observers get :data:`~lapwrench.sim.camera.NO_IMAGE`.

    ``render_in_background`` draws the camera's frames in a child process while the loop steps on
    (:meth:`_camera_step`): the same images, handed over with their capture times, the detector's
    results published at the same simulated times; a frame still being drawn when a run ends is handed
    over by :meth:`flush_frames` or :meth:`close`. It pays off when a core is free (a single run, the
    bench), not when every core already runs a scenario."""

    def __init__(
        self,
        cfg: Config,
        seed: int = 0,
        *,
        detector: str | None = None,
        detection_latency: float | None = None,
        scene_config: SceneConfig | None = None,
        on_frame: Callable[[np.ndarray, float, str], None] | None = None,
        world: WorldVariation | None = None,
        render_in_background: bool = False,
        detector_threads: int | None = None,
    ) -> None:
        self.cfg = cfg
        self.seed = seed
        self.variation = world or WorldVariation()
        sc = self.variation.scene(scene_config or SceneConfig.from_config(cfg))
        self.world = SimWorld(built_scene(sc))
        self.world.reset()
        self.model = RobotModel(sc.kind, sc.scope)
        self.controller = Controller(cfg, self.model)
        rng = np.random.SeedSequence(seed)
        # the 4th stream (detector corruption) leaves the first three as they were with spawn(3)
        s_ft, s_tac, s_obs, s_det = (int(x.generate_state(1)[0]) for x in rng.spawn(4))
        self.ft = SimForceTorqueSensor(self.world, seed=s_ft)
        self.tactile = TactileGripModel(seed=s_tac)
        bias = arm_spec(sc.kind).sim_torque_bias
        self.robot = SimRobot(
            self.world, estimate=ForceEstimateConfig(torque_noise=TORQUE_NOISE, torque_bias=bias, seed=s_obs),
            model=self.model,
        )
        # the same measured-state bounds as on the robot; compute time measured, no wall-clock deadline
        self.supervisor = SafetySupervisor(
            self.model.limits, CONTROL_DT, SupervisorConfig.from_config(cfg, max_consecutive_misses=0)
        )
        observers = list(_OBSERVERS)
        self._frame_observers: list[FrameObserver] = [
            frame for f in observers if callable(frame := getattr(f, "frame", None))
        ]
        latency_s = self.variation.detector_latency_s if detection_latency is None else detection_latency
        # Frames drawn in a child process while the loop steps on (see _camera_step): not for a
        # measured latency (known only once detected) nor for live telemetry (it reads the loop's state).
        background = render_in_background and latency_s != "measured" and not self._frame_observers
        # the projected detector alone needs the camera's clock, not its images (live telemetry is then
        # handed empty frames, and draws the few it sends itself)
        draw = on_frame is not None or detector not in (None, "projected")
        self.camera = (SimCamera(self.world, background=background, draw=draw)
                       if detector is not None or on_frame is not None else None)
        self.detection: SimulatedAsyncDetector | None = None
        self.detector_name = "none"
        if detector is not None:
            det, self.detector_name = make_detector(detector, self.world, cfg, detector_threads)
            v = self.variation
            if v.detector_corrupted:
                det = CorruptedDetector(det, v.detector_dropout, v.detector_noise_px, seed=s_det)
                self.detector_name += v.describe_detector()
            assert self.camera is not None  # built whenever there is a detector
            self.detection = SimulatedAsyncDetector(det, frame_rate=self.camera.fps, latency=latency_s)
        self.on_frame = on_frame
        self.last_mode = "idle"
        self.ft.tare()
        self.grip_force = 0.0
        self.t = 0.0
        # The image-free detector reads the world's geometry: it detects at the capture time, even
        # when the frame is drawn in the background.
        self._detect_at_capture = detector == "projected"
        self._pending: PendingFrame | None = None
        self._hold = frame_hold(self.camera.fps if self.camera else 1.0, latency_s, self._detect_at_capture
                                 or detector is None)

        def notify(c: Cycle) -> None:
            for f in observers:
                f(self, c)

        self.loop = ControlLoop(
            self.robot, self.controller, self.supervisor, self._sources(), clock=lambda: self.t,
            wall_deadlines=False, switch_interval=None, on_cycle=notify if observers else None,
        )
        self._reading = self.loop.start()
        self.q0 = self._reading.q
        self.events: list[object] = []
        self.compute_us: list[float] = []
        self._cue_keys: dict[str, str] = {}

    def _sources(self) -> list[Source]:
        """The controller's inputs, each a simulated source sampled every control period (their own
        models hold the sensors' rates, noise and latency)."""
        ages = self.cfg.inputs
        out: list[Source] = [
            Observable("ft", self.ft.read, update_interval=CONTROL_DT, max_age=0.02),
            Observable("tactile", lambda t: self.tactile.read(t, self.grip_force), update_interval=CONTROL_DT,
                       max_age=0.1),
        ]
        if self.detection is not None:
            out.append(Observable("instruments", self._observation, update_interval=CONTROL_DT,
                                  max_age=ages.max_image_age))
        for i, spec in enumerate(input_specs(self.controller.cues).values()):  # inputs the plugin cues ask for
            out.append(simulated_input(spec, self.world, seed=self.seed + i))
        return out

    @property
    def time(self) -> float:
        return self.t

    @property
    def detector_description(self) -> str:
        """The detector, its frame rate, its modelled latency and its measured inference time."""
        if self.detection is None:
            return self.detector_name
        lat = self.detection.latency
        latency = "measured" if lat == "measured" else f"{float(lat) * 1e3:.0f} ms"
        times = self.detection.compute_seconds
        inference = f", inference median {np.median(times) * 1e3:.1f} ms (wall time)" if times else ""
        return (f"{self.detector_name}, {self.detection.frame_rate:.0f} fps, asynchronous, "
                f"capture-to-use latency {latency}{inference}")

    def _camera_step(self, t: float) -> None:
        """The camera at ``t``: a due frame is drawn and handed to its users (the frame callback, live
        telemetry, the detector) with its capture time and the mode at capture.

        With ``render_in_background`` it is drawn in a child process while the loop steps on, and handed
        over at the latest when it is needed: before the tick at which the detector's result on it is
        due (capture + latency; the detector's own schedule publishes it then, as before) and before
        the next frame. :meth:`flush_frames` hands over a frame still being drawn."""
        cam = self.camera
        if cam is None:
            return
        if self._pending is not None and t >= self._pending.deliver_by:
            self._deliver_frame()
        if cam.offscreen is None:  # drawn now (or not drawn at all: the clock alone)
            if cam.capture(t):
                assert cam.frame is not None  # set by a capture (NO_IMAGE when the camera does not draw)
                self._publish(cam.frame, t, self.last_mode, detect=True)
            return
        if not cam.begin(t):
            return
        if self._detect_at_capture and self.detection is not None:
            self.detection.offer(t, NO_IMAGE)  # detects from the geometry now; the frame follows
        # handed over a tick before it is needed: the detector's result is then in its queue for anyone
        # asking between two ticks, as when the frame is drawn at once
        self._pending = PendingFrame(t, self.last_mode, t + self._hold - 1.5 * CONTROL_DT)
        if self._hold < 2.5 * CONTROL_DT:  # needed within two ticks: no time to overlap
            self._deliver_frame()

    def _deliver_frame(self) -> None:
        p, self._pending = self._pending, None
        assert p is not None and self.camera is not None
        self._publish(self.camera.finish(), p.t, p.mode, detect=not self._detect_at_capture)

    def _publish(self, frame: np.ndarray, t: float, mode: str, *, detect: bool) -> None:
        if self.on_frame is not None:
            self.on_frame(frame, t, mode)
        for observer in self._frame_observers:  # live telemetry (observe_cycles) that takes frames too
            observer(self, frame, t)
        if detect and self.detection is not None:
            self.detection.offer(t, frame)

    def flush_frames(self) -> None:
        """Hand over the frame still being drawn in the background, if any (call at the end of a run
        whose frames are all wanted, e.g. for a video)."""
        if self._pending is not None:
            self._deliver_frame()

    def close(self) -> None:
        """:meth:`flush_frames`, then end the camera's render process and free the world's renderers."""
        self.flush_frames()
        if self.camera is not None:
            self.camera.close()
        self.world.close()

    def _observation(self, t: float) -> InstrumentObservation | None:
        return None if self.detection is None else self.detection.observation(t)

    def step(self, grip_force: float, before_physics: Callable[[float], None] | None = None) -> TickResult:
        """One 1 ms cycle of the control loop: sensors → controller → supervisor → robot. The hand
        wrench must already be set.

        The supervisor watches *measured* state only: the RCM error and the insertion depth at the
        joints the robot reads (:func:`~lapwrench.safety.supervisor.measure_scope`, for the
        controller's p_R) and the residual ΔF of the controller's sensors; the simulator's ground
        truth (:meth:`physical_rcm_error`, the contact force) is for metrics only. An exception
        from the controller's tick is an alarm too.

        Raises:
            SafetyStopError: the supervisor raised an alarm; the arm was first brought to rest
                with the supervisor's jerk-limited stop (this tick's command is its first sample).
        """
        t = self.t
        self._camera_step(t)
        self.grip_force = grip_force
        self.loop.before_command = before_physics
        c = self.loop.cycle()
        self.events.extend(c.events)
        self.compute_us.append(c.compute * 1e6)
        if c.result is not None:
            self.last_mode = c.result.mode
        self.t = t + CONTROL_DT
        if self.supervisor.alarm:
            self.flush_frames()
            self._stop_to_rest()
            raise SafetyStopError(t, self.supervisor.alarm_reason)
        assert c.result is not None  # a failed tick raised the alarm above
        return c.result

    def _stop_to_rest(self) -> None:
        """After an alarm: keep sending the supervisor's jerk-limited stop until the arm is at rest."""
        self.loop.on_events = self.events.extend
        for _ in range(10_000):
            if self.supervisor.at_rest:
                break
            self.loop.hold_cycle()
            self.t += CONTROL_DT

    def physical_rcm_error(self) -> float:
        """Distance (m) from the unloaded incision point (where the wall would sit with no shaft
        load) to the shaft axis: how far the scope drags the incision. The trocar's own position
        always lies on the axis, so this is the physically meaningful RCM error.

        Eq (27)'s |e_R| (:meth:`SimWorld.axis_offset`), with the simulated scope's pose and the
        unloaded incision in place of the model's p_E and the controller's p_R."""
        return self.world.axis_offset(self.world.incision_rest_position())[0]

    def record(self, trace: Trace, res: TickResult, **extra: object) -> None:
        """One row of ``trace``: the run's state, and every cue's wrench (``cue:<name>``, 6-vector) and
        telemetry (``cue:<name>.<field>``), whatever cues the configuration runs."""
        w = self.world
        p_E, d_z = w.shaft_axis()
        incision = w.incision_position()
        wrenches = res.wrenches
        keys = self._cue_keys  # "cue:<name>" made once per name, not every tick
        cues: dict[str, object] = {keys.get(n) or keys.setdefault(n, f"cue:{n}"): v for n, v in wrenches.items()}
        for cue in self.controller.python_cues:
            values = (res.telemetry or {}).get(cue.name, ())
            for field_name, x in zip(cue.telemetry_fields, values, strict=False):
                cues[f"cue:{cue.name}.{field_name}"] = x
        trace.add(
            **cues,
            t=res.time,
            mode=res.mode,
            delta=res.delta,
            rcm_error_ctrl=res.rcm_error,
            rcm_error_phys=self.physical_rcm_error(),
            contact_force=w.contact_force(),
            W_h=wrenches.get("interaction", _ZERO_WRENCH),
            W_c=wrenches.get("tracking", _ZERO_WRENCH),
            p_R=res.p_R,
            incision=incision,
            p_E=p_E,
            d_z=d_z,
            q_ref=res.q_ref,
            hand_force=w.hand_force(),
            hand_torque=w.hand_torque(),
            insertion_depth=float((incision - p_E) @ d_z),  # SimWorld.insertion_depth, from the poses read above
            **extra,
        )
