"""The simulated world: one true timeline that every simulated device observes.

`advance(dt)` steps the scene's actuators and the skin mechanics at the mechanical rate, in
stretches: the scene plans the steps open loop, the skin mechanics run the stretch in one
compiled call, and a stretch ends at the first step after which the scene reacts to the load
(the gripper's jaws stop at their force setting). The samplers (the F/T sensor) take
the samples that fall under it, each holding the last step before it. A sampler reports the
first sample on which a safety guard would trip; the world then rewinds the stretch to that
sample's step, lets the guard act on the scene there (so a trip stops motion from the next step
on, exactly as if every step had been taken one by one) and goes on from there. At the end of
the advance the batched streams (skin frames, stage/arm/gripper states, camera images) sample
what happened, each at its own device times, holding the step at or before each sample
(zero-order hold).
"""

from __future__ import annotations

import json
from collections.abc import Callable

import numpy as np

from layerskin_exp.config import SkinConfig
from layerskin_exp.sim import mechanics as mk
from layerskin_exp.sim.clocks import DeviceClock, device_rng, lognormal_unit_mean
from layerskin_exp.sim.rig_config import DeviceClockConfig, RigConfig
from layerskin_exp.sim.streams import Stream

# Batched stream producer: (world, t_s (N,), state index per sample (N,)) -> None.
Producer = Callable[["World", np.ndarray, np.ndarray], None]
# Sampler: (world, step times (m,), step records (m, STEP_FIELDS), t_to_s, act) -> None or the
# index of the step under the first sample on which a guard would trip (see add_sampler).
Sampler = Callable[["World", np.ndarray, np.ndarray, float, bool], "int | None"]


class World:
    """Scene + skin model + streams on one virtual timeline.

    scene: PlatformScene or GripScene (actuators and the indenter pose they give; plan/commit of
    a stretch of steps, first_reaction/after_step to the load, indenter_pose, snapshot).
    skin_model: SkinModel (step_many, state_of, mech_state/restore_mech_state, frames).
    """

    def __init__(self, rig: RigConfig, skin: SkinConfig, seed: int, scene, skin_model) -> None:
        self.rig = rig
        self.skin_cfg = skin
        self.seed = int(seed)
        self.scene = scene
        self.skin_model = skin_model
        self.mech_dt_s = 1.0 / rig.mech_rate_hz
        self.host_start_ns = int(round(rig.host_start_s * 1e9))
        self.t_s = 0.0
        self._tick = 0
        self.streams: dict[str, Stream] = {}
        self._producers: list[tuple[Stream, Producer]] = []
        self._samplers: list[Sampler] = []
        self._prepare: list[Callable] = []
        self._trial_hooks: list[Callable[[World], None]] = []
        self.trial_key = ""  # labels of the current trial (canonical JSON); "" before the first
        xyz, yaw = scene.indenter_pose()
        rec = skin_model.step_many(np.zeros(1), np.asarray(xyz, float).reshape(1, 3), np.array([yaw], float))
        scene.after_step(float(rec[0, mk.S_FZ]))
        # Step records of the current advance, in stretches; the first is the last step before it.
        self._recs: list[np.ndarray] = [rec]
        self._snaps: list[np.ndarray] = [np.asarray(scene.snapshot(), float).reshape(1, -1)]
        self._rec_all: np.ndarray | None = None
        self._snap_all: np.ndarray | None = None
        self._state = (None, None)  # (record, MechState) of the last step

    # ---- time --------------------------------------------------------------------------------
    def host_now_ns(self) -> int:
        return self.host_start_ns + int(round(self.t_s * 1e9))

    def new_stream(self, name: str, clock_cfg: DeviceClockConfig, period_s: float,
                   period_jitter_s: float = 0.0) -> Stream:
        clock = DeviceClock(clock_cfg, device_rng(self.seed, name + ".clock"), self.host_start_ns)
        s = Stream(name, clock, period_s, device_rng(self.seed, name + ".stream"), period_jitter_s, self.t_s)
        self.streams[name] = s
        return s

    # ---- trials ------------------------------------------------------------------------------
    def rng(self, name: str) -> np.random.Generator:
        """A generator for one named part of the world in the current trial (seed + trial labels)."""
        return device_rng(self.seed, f"{name}|{self.trial_key}" if self.trial_key else name)

    def on_trial(self, hook: Callable[[World], None]) -> None:
        """Register hook(world), called at each begin_trial after the world's own re-draws
        (devices re-seed their noise from world.rng(name) there)."""
        self._trial_hooks.append(hook)

    def begin_trial(self, labels: dict) -> None:
        """Start a new trial: new noise, jitter and delay draws, and the bench's trial-to-trial
        variation (cover friction; the rod's placement on the grip rig), all from the seed and the
        labels only. Sensor properties drawn at construction (taxel gains, baselines, clock
        offsets and drifts, F/T bias) stay: the same devices are used throughout."""
        self.trial_key = json.dumps(labels, sort_keys=True, default=str)
        for name, stream in self.streams.items():
            stream.rng = self.rng(name + ".stream")
            stream.clock.reseed(self.rng(name + ".clock"))
        if hasattr(self.skin_model, "reseed"):
            self.skin_model.reseed(self.rng("skin_model.noise"))
        var = self.rig.variation
        rng = self.rng("variation")
        factor = float(lognormal_unit_mean(rng, var.friction_cv))
        if hasattr(self.skin_model, "friction"):
            self.skin_model.friction.set_surface_factor(factor)
        if hasattr(self.scene, "begin_trial"):
            self.scene.begin_trial(rng, var)
        for hook in self._trial_hooks:
            hook(self)

    def add_producer(self, stream: Stream, produce: Producer) -> None:
        """Register a batched stream: produce(world, t_s, idx) is called once per advance."""
        self._producers.append((stream, produce))

    def add_sampler(self, sample: Sampler, prepare: Callable[[World, float], None] | None = None) -> None:
        """Register a device that samples the mechanics at its own times between steps.

        prepare(world, t_end_s), if given, runs once at the start of each advance (the device can
        schedule and stamp its samples of the advance there). sample(world, t, recs, t_to_s, act)
        takes the device's due samples up to and including t_to_s, each holding the last step
        strictly before it (t (m,) step times, recs (m, STEP_FIELDS) their records). With
        act=False it stops before the first sample on which a safety guard would trip and returns
        the index of that sample's step, leaving the sample untaken; the world then rewinds to
        that step and calls it again with act=True, where it takes its samples and lets the
        guards act on them."""
        self._samplers.append(sample)
        if prepare is not None:
            self._prepare.append(prepare)

    # ---- stepping ----------------------------------------------------------------------------
    def advance(self, dt_s: float) -> None:
        """Let dt_s seconds of world time pass."""
        if dt_s < 0:
            raise ValueError(f"cannot advance by a negative time {dt_s} s")
        t_end = self.t_s + dt_s
        dt = self.mech_dt_s
        scene, model = self.scene, self.skin_model
        for prepare in self._prepare:
            prepare(self, t_end)
        # steps at (tick + k) dt <= t_end, k = 1..n_steps (estimate low, then settle exactly)
        n_steps = max(int((t_end + 1e-12) / dt) - self._tick - 1, 0)
        while (self._tick + n_steps + 1) * dt <= t_end + 1e-12:
            n_steps += 1
        prev = self._recs[-1][-1:]  # the last step: samples before the next one hold it
        if n_steps == 0:
            self._sample(prev[:, mk.S_T], prev, t_end)
        while n_steps > 0:
            m = n_steps
            t_k = (self._tick + 1 + np.arange(m)) * dt
            xyz, yaw, snap, token = scene.plan(m, dt)
            saved = model.mech_state()
            recs = model.step_many(t_k, xyz, yaw)
            # the scene reacting to the load (the jaws' force stop) ends the stretch at that step
            react = scene.first_reaction(token, recs)
            if react is not None and react < m - 1:
                m = react + 1
                t_k, xyz, yaw, snap = t_k[:m], xyz[:m], yaw[:m], snap[:m]
                model.restore_mech_state(saved)
                recs = model.step_many(t_k, xyz, yaw)
            # the samplers see [previous step, this stretch]: a trip at index j keeps j steps
            trip = self._sample(np.concatenate((prev[:, mk.S_T], t_k)), np.concatenate((prev, recs)),
                                min(t_k[-1] + dt, t_end), probe=True) if self._samplers else None
            if trip is not None and trip < m:
                model.restore_mech_state(saved)
                if trip == 0:  # under the previous step: the guard acts there, then plan again
                    self._sample(prev[:, mk.S_T], prev, t_k[0])
                    continue
                m = trip
                t_k, xyz, yaw, snap = t_k[:m], xyz[:m], yaw[:m], snap[:m]
                recs = model.step_many(t_k, xyz, yaw)
            scene.commit(token, m - 1)
            if scene.after_step(float(recs[-1, mk.S_FZ])):  # it reacted: the last snapshot shows it
                snap = snap.copy()
                snap[-1] = scene.snapshot()
            if trip is not None:  # the tripping sample and the rest under this stretch's last step
                self._sample(t_k, recs, min(t_k[-1] + dt, t_end))
            self._recs.append(recs)
            self._snaps.append(snap)
            self._tick += m
            n_steps -= m
            self.t_s = float(t_k[-1])
            prev = recs[-1:]
        self.t_s = t_end
        self._run_producers(t_end)

    def _sample(self, t_k: np.ndarray, recs: np.ndarray, t_to: float, probe: bool = False) -> int | None:
        """Run the samplers over steps t_k (m,) with records recs (m, STEP_FIELDS) up to t_to; with
        probe, the index into t_k of the step under the first sample that would trip (or None)."""
        trip = None
        for sample in self._samplers:
            j = sample(self, t_k, recs, t_to, not probe)
            if j is not None and (trip is None or j < trip):
                trip = j
        return trip

    def _run_producers(self, t_end: float) -> None:
        self._rec_all = recs = self._recs[0] if len(self._recs) == 1 else np.concatenate(self._recs)
        self._snap_all = None
        times = recs[:, mk.S_T]
        for stream, produce in self._producers:
            t_s = stream.due_times(t_end)
            if len(t_s) == 0 or not stream.enabled:
                continue
            idx = np.searchsorted(times, t_s, side="right") - 1
            produce(self, t_s, np.maximum(idx, 0))
        # Keep only the last step as the hold value for the next advance.
        self._recs = [recs[-1:]]
        self._snaps = [self.snapshots(np.array([len(recs) - 1]))]
        self._rec_all = self._snap_all = None

    # ---- what happened in this advance (for the producers) ----------------------------------
    def records(self, idx: np.ndarray) -> np.ndarray:
        """(N, STEP_FIELDS) step records at the given step indices of this advance."""
        return self._rec_all[idx]

    def snapshots(self, idx: np.ndarray) -> np.ndarray:
        """(N, K) scene snapshots (actuator positions) at the given step indices of this advance."""
        if self._snap_all is None:  # once per advance, shared by the producers
            self._snap_all = self._snaps[0] if len(self._snaps) == 1 else np.concatenate(self._snaps)
        return self._snap_all[idx]

    def states(self, idx: np.ndarray) -> list:
        """MechStates at the given step indices of this advance."""
        recs = self._rec_all[idx]
        return [self.skin_model.state_of(r) for r in recs]

    @property
    def state(self):
        """MechState of the last step taken."""
        chunk = self._recs[-1]
        if self._state[0] is not chunk:
            self._state = (chunk, self.skin_model.state_of(chunk[-1]))
        return self._state[1]
