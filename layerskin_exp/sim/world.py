"""The simulated world: one true timeline that every simulated device observes.

`advance(dt)` steps the scene's actuators and the skin mechanics at the mechanical rate; after
each step it emits the F/T samples that fall before the next step (and runs the rig's safety
guards on each, at that sample's time, so a trip stops motion from the next step on). At the
end of the advance the batched streams (skin frames, stage/arm/gripper states, camera images)
sample what happened, each at its own device times, holding the mechanical state of the last
step at or before each sample (zero-order hold).
"""

from __future__ import annotations

import json
from collections.abc import Callable

import numpy as np

from layerskin_exp.config import SkinConfig
from layerskin_exp.sim.clocks import DeviceClock, device_rng, lognormal_unit_mean
from layerskin_exp.sim.rig_config import DeviceClockConfig, RigConfig
from layerskin_exp.sim.streams import Stream

# Batched stream producer: (world, t_s (N,), state index per sample (N,)) -> None.
Producer = Callable[["World", np.ndarray, np.ndarray], None]


class World:
    """Scene + skin model + streams on one virtual timeline.

    scene: PlatformScene or GripScene (actuators and the indenter pose they give).
    skin_model: object with step(t_s, xyz_mm, yaw_rad) -> MechState and frames(states, t_s).
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
        self._per_tick: list[Callable] = []
        self._prepare: list[Callable] = []
        self._snap_array: np.ndarray | None = None
        self._trial_hooks: list[Callable[[World], None]] = []
        self.trial_key = ""  # labels of the current trial (canonical JSON); "" before the first
        # Step records of the current advance; element 0 is the last step before it.
        xyz, yaw = scene.indenter_pose()
        self.state = skin_model.step(0.0, np.asarray(xyz, float), yaw)
        scene.after_state(self.state)
        self._rec_t = [0.0]
        self._rec_states = [self.state]
        self._rec_snap = [scene.snapshot()]

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

    def add_per_tick(self, fn: Callable[[World, float, float], None],
                     prepare: Callable[[World, float], None] | None = None) -> None:
        """Register fn(world, t_from_s, t_to_s), called after each step for the samples after
        t_from_s up to and including t_to_s (the last step's state holds for them).
        prepare(world, t_end_s), if given, runs once at the start of each advance (a device can
        schedule and stamp all of its samples of the advance at once there)."""
        self._per_tick.append(fn)
        if prepare is not None:
            self._prepare.append(prepare)

    # ---- stepping ----------------------------------------------------------------------------
    def advance(self, dt_s: float) -> None:
        """Let dt_s seconds of world time pass."""
        if dt_s < 0:
            raise ValueError(f"cannot advance by a negative time {dt_s} s")
        t_end = self.t_s + dt_s
        dt = self.mech_dt_s
        scene, model, per_tick = self.scene, self.skin_model, self._per_tick
        rec_t, rec_states, rec_snap = self._rec_t, self._rec_states, self._rec_snap
        for prepare in self._prepare:
            prepare(self, t_end)
        # Per-tick samples between the previous step and the next one still belong to the last state.
        if per_tick:
            next_tick_t = (self._tick + 1) * dt
            for fn in per_tick:
                fn(self, self.t_s, min(next_tick_t, t_end))
        while (self._tick + 1) * dt <= t_end + 1e-12:
            self._tick += 1
            t_k = self._tick * dt
            scene.step(dt)
            xyz, yaw = scene.indenter_pose()
            self.state = state = model.step(t_k, np.asarray(xyz, float), yaw)
            scene.after_state(state)
            rec_t.append(t_k)
            rec_states.append(state)
            rec_snap.append(scene.snapshot())
            self.t_s = t_k
            if per_tick:
                t_to = min(t_k + dt, t_end)
                for fn in per_tick:
                    fn(self, t_k, t_to)
        self.t_s = t_end
        self._run_producers(t_end)

    def _run_producers(self, t_end: float) -> None:
        times = np.asarray(self._rec_t)
        self._snap_array = None
        for stream, produce in self._producers:
            t_s = stream.due_times(t_end)
            if len(t_s) == 0 or not stream.enabled:
                continue
            idx = np.searchsorted(times, t_s, side="right") - 1
            produce(self, t_s, np.maximum(idx, 0))
        # Keep only the last step as the hold value for the next advance.
        del self._rec_t[:-1], self._rec_states[:-1], self._rec_snap[:-1]
        self._snap_array = None

    def snapshots(self, idx: np.ndarray) -> np.ndarray:
        """(N, K) scene snapshots (actuator positions) at the given step indices of this advance."""
        if self._snap_array is None:  # once per advance, shared by the producers
            self._snap_array = np.asarray(self._rec_snap, dtype=float)
        return self._snap_array[idx]

    def states(self, idx: np.ndarray) -> list:
        return [self._rec_states[i] for i in idx]

